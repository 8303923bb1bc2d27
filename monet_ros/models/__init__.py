"""Heatmap keypoint detectors (CPM, Hourglass, a small fast net), codec and checkpoints."""
from monet_ros.models.checkpoint import (
    CheckpointError,
    load_checkpoint,
    read_checkpoint,
    save_checkpoint,
)
from monet_ros.models.crop import (
    crop_images,
    crop_to_original,
    fit_boxes_to_aspect,
    full_frame_boxes,
)
from monet_ros.models.detector import Detector, images_to_tensor
from monet_ros.models.heatmaps import (
    decode_heatmap_peaks,
    decode_heatmap_views,
    decode_heatmaps,
    labelled_mask,
    render_heatmaps,
)
from monet_ros.models.layers import fuse_for_inference
from monet_ros.models.registry import MODELS, build_model

__all__ = [
    'CheckpointError', 'Detector', 'MODELS', 'build_model', 'crop_images', 'crop_to_original',
    'decode_heatmap_peaks', 'decode_heatmap_views', 'decode_heatmaps', 'fit_boxes_to_aspect',
    'full_frame_boxes', 'fuse_for_inference', 'images_to_tensor',
    'labelled_mask', 'load_checkpoint', 'read_checkpoint', 'render_heatmaps',
    'save_checkpoint',
]
