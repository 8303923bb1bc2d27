"""Skeleton visualisation markers as plain specs (no ROS types): one SPHERE_LIST for the
joints and one LINE_LIST for the bones; convert.py and writer.py turn them into
visualization_msgs/Marker of their own flavour."""
import numpy as np

SPHERE_LIST = 7   # visualization_msgs/Marker constants
LINE_LIST = 5


def skeleton_marker_specs(X, bone_indices, ns='monet', scale=0.03):
    """X (N, 3) keypoints (NaN = missing), bone_indices (B, 2) -> list of two dicts
    (ns, id, type, scale (3,), color rgba (4,), points (M, 3)). NaN joints and bones with
    a NaN end are left out."""
    X = np.asarray(X, np.float64).reshape(-1, 3)
    bones = np.asarray(bone_indices, np.int64).reshape(-1, 2)
    if bones.size and (bones.min() < 0 or bones.max() >= len(X)):
        raise ValueError(f'bone index out of range for {len(X)} keypoints')
    finite = np.isfinite(X).all(axis=1)
    ok = finite[bones[:, 0]] & finite[bones[:, 1]] if bones.size else np.zeros(0, bool)
    line_points = X[bones[ok].reshape(-1)] if bones.size else np.zeros((0, 3))
    return [
        dict(ns=ns, id=0, type=SPHERE_LIST, scale=(scale, scale, scale),
             color=(1.0, 0.3, 0.1, 1.0), points=X[finite]),
        dict(ns=ns, id=1, type=LINE_LIST, scale=(scale / 3.0, 0.0, 0.0),
             color=(0.1, 0.8, 1.0, 1.0), points=line_points),
    ]
