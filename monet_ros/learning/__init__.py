"""Losses (epipolar divergence), datasets from recordings, pseudo-labels and training."""
