"""3D over time (no ROS): offline filters of triangulated keypoints over a whole
recording (a Kalman / RTS smoother with outlier gating, a spatiotemporal least-squares
optimisation with bone lengths), gap bridging and bone-length estimation, used by
`monet process --filter` and `monet triangulate --filter`; and the fusion node's live
causal filter (temporal.live).
"""
from monet_ros.temporal.bones import bone_lengths
from monet_ros.temporal.config import LOSSES, METHODS, FilterConfig
from monet_ros.temporal.gaps import bridgeable, frames_for
from monet_ros.temporal.kalman import KalmanResult, kalman_smooth
from monet_ros.temporal.optim import OptimResult, optimise
from monet_ros.temporal.smooth import Smoothed, reprojection_stats, smooth_points

__all__ = ['bone_lengths', 'bridgeable', 'FilterConfig', 'frames_for', 'KalmanResult',
           'kalman_smooth', 'LOSSES', 'METHODS', 'OptimResult', 'optimise',
           'reprojection_stats', 'Smoothed', 'smooth_points']
