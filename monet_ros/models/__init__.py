"""Heatmap keypoint detectors (CPM, Hourglass, a small fast net), codec and checkpoints."""
from monet_ros.models.checkpoint import (
    CheckpointError,
    load_checkpoint,
    read_checkpoint,
    save_checkpoint,
)
from monet_ros.models.heatmaps import decode_heatmaps, labelled_mask, render_heatmaps
from monet_ros.models.layers import fuse_for_inference
from monet_ros.models.registry import MODELS, build_model

__all__ = [
    'CheckpointError', 'MODELS', 'build_model', 'decode_heatmaps', 'fuse_for_inference',
    'labelled_mask', 'load_checkpoint', 'read_checkpoint', 'render_heatmaps',
    'save_checkpoint',
]
