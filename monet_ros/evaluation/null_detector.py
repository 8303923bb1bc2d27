"""The image-blind null detector: the mean labelled pose in the crop, whatever the image.

Every benchmark table has its row: a mode that does not beat it on a ground-truth column
has learned nothing that the crop rule did not already give away. Its heatmaps are
Gaussians (the training target, same sigma) at the mean heatmap position of every
keypoint over the labelled training views, cropped by the training crop rule; it runs
through models.Detector and the evaluation like any trained network.
"""
import numpy as np
import torch

from monet_ros.models.heatmaps import render_heatmaps

ARCHITECTURE = 'null_mean_pose'


class MeanPoseNet(torch.nn.Module):
    """A constant 'network': (N, 3, H, W) images -> [(N, C, h, w)] fixed heatmaps.

    positions (C, 2) heatmap pixels (u, v); input_size (H, W); heatmap_size (h, w); sigma
    heatmap px. Same interface as the detectors of models.build_model."""

    architecture = ARCHITECTURE

    def __init__(self, positions, input_size, heatmap_size, sigma):
        super().__init__()
        positions = np.asarray(positions, np.float64)
        if positions.ndim != 2 or positions.shape[1] != 2 or not np.isfinite(positions).all():
            raise ValueError(f'MeanPoseNet: positions must be finite (C, 2), got '
                             f'{positions.shape}')
        self.num_keypoints = len(positions)
        self.input_size = tuple(int(x) for x in input_size)
        self.heatmap_size = tuple(int(x) for x in heatmap_size)
        heat = render_heatmaps(torch.as_tensor(positions[None], dtype=torch.float32),
                               self.heatmap_size, sigma)
        self.register_buffer('heat', heat.float())

    def forward(self, images):
        return [self.heat.expand(images.shape[0], -1, -1, -1)]


def mean_pose_positions(data):
    """(C, 2) mean heatmap position of every keypoint over the labelled training views of a
    learning.trainer.TrainingData, in its (unaugmented) training crops. Raises ValueError
    when a keypoint is never labelled."""
    pairs = np.argwhere(np.isfinite(data.labels[..., 0]).any(axis=2))         # (N, 2) (t, v)
    batch = data.cache.views(pairs[:, 0], pairs[:, 1])                         # no augmentation
    points = batch.to_heatmap(data.labels[pairs[:, 0], pairs[:, 1]])          # (N, C, 2)
    counts = np.isfinite(points[..., 0]).sum(axis=0)
    if (counts == 0).any():
        missing = [data.recording.keypoints[c] for c in np.flatnonzero(counts == 0)]
        raise ValueError(f'null detector: keypoints never labelled: {missing}')
    return np.nanmean(points, axis=0)


def null_detector(data, sigma, device='cpu'):
    """models.Detector of the mean pose of `data` (a TrainingData) at its crop sizes."""
    from monet_ros.models.detector import Detector

    net = MeanPoseNet(mean_pose_positions(data), data.cache.input_size,
                      data.cache.heatmap_size, sigma)
    return Detector(net, {'keypoints': list(data.recording.keypoints),
                          'architecture': ARCHITECTURE}, device=device, fuse=False)
