"""Several subjects (no ROS): association of per-camera instances across cameras
(subjects.association) and identities over time (subjects.tracking), identity metrics
(subjects.metrics). Used by `monet triangulate --subjects` and bench/subjects.py."""
from monet_ros.subjects.association import (
    Association,
    AssociationConfig,
    associate,
)

__all__ = ['Association', 'AssociationConfig', 'associate']
