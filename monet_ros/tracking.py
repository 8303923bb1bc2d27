"""Crop boxes around the subject's last 3D keypoints: see monet_ros.crop_rule (the one crop
rule); these names stay importable from here."""
from monet_ros.crop_rule import TrackedCrops, crop_boxes, subject_boxes  # noqa: F401
