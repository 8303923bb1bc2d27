"""Heatmap keypoint detectors (CPM, Hourglass, a small fast net), codec and checkpoints."""
