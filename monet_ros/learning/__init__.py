"""Losses (epipolar divergence), datasets from recordings, pseudo-labels and training."""
from monet_ros.learning.epipolar import (
    epipolar_divergence,
    multiview_epipolar_loss,
    rectify_pair,
    valid_view_pairs,
)

__all__ = [
    'epipolar_divergence', 'multiview_epipolar_loss', 'rectify_pair', 'valid_view_pairs',
]
