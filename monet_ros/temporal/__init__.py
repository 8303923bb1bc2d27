"""Temporal filtering of 3D keypoints (no ROS): the live causal filter of the fusion node
(temporal.live) and the offline smoothers of `monet process --filter`."""
