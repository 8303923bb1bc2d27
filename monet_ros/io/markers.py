"""Visualisation markers as plain specs (no ROS types): the skeleton (a SPHERE_LIST for the
joints, a LINE_LIST for the bones, optional TEXT_VIEW_FACING joint names) and the rig's
camera frustums (a LINE_LIST per camera + its name); convert.py and writer.py turn them into
visualization_msgs/Marker of their own flavour.

A spec is a dict: ns, id, type, scale (3,), color rgba (4,), points (M, 3), and for text
markers `text` and `position` (3,).
"""
import numpy as np

LINE_LIST = 5      # visualization_msgs/Marker constants
SPHERE_LIST = 7
TEXT_VIEW_FACING = 9
DELETEALL = 3


# Joint and bone colours (rgba) of subject identity i: SUBJECT_COLOURS[i % 6] (subject 0 is
# the one-subject colours).
SUBJECT_COLOURS = (
    ((1.0, 0.3, 0.1, 1.0), (0.1, 0.8, 1.0, 1.0)),      # orange / sky
    ((0.2, 0.9, 0.2, 1.0), (0.9, 0.2, 0.9, 1.0)),      # green / magenta
    ((1.0, 0.9, 0.1, 1.0), (0.3, 0.3, 1.0, 1.0)),      # yellow / blue
    ((0.9, 0.1, 0.3, 1.0), (0.2, 1.0, 0.8, 1.0)),      # red / aqua
    ((0.6, 0.3, 1.0, 1.0), (1.0, 0.6, 0.2, 1.0)),      # violet / amber
    ((1.0, 1.0, 1.0, 1.0), (0.5, 0.5, 0.5, 1.0)),      # white / grey
)


def skeleton_marker_specs(X, bone_indices, ns='monet', scale=0.03, names=None, subject=0):
    """X (N, 3) keypoints (NaN = missing), bone_indices (B, 2) -> list of dicts: joints
    (id 0), bones (id 1), and with `names` (N keypoint names) one text marker per finite
    joint (id 2 + keypoint index), just above it. NaN joints and bones with a NaN end are
    left out. subject: the identity whose colours (SUBJECT_COLOURS) are used. Raises
    ValueError for a bone index out of range or a wrong number of names."""
    X = np.asarray(X, np.float64).reshape(-1, 3)
    bones = np.asarray(bone_indices, np.int64).reshape(-1, 2)
    if bones.size and (bones.min() < 0 or bones.max() >= len(X)):
        raise ValueError(f'bone index out of range for {len(X)} keypoints')
    finite = np.isfinite(X).all(axis=1)
    ok = finite[bones[:, 0]] & finite[bones[:, 1]] if bones.size else np.zeros(0, bool)
    line_points = X[bones[ok].reshape(-1)] if bones.size else np.zeros((0, 3))
    joints, lines = SUBJECT_COLOURS[int(subject) % len(SUBJECT_COLOURS)]
    specs = [
        dict(ns=ns, id=0, type=SPHERE_LIST, scale=(scale, scale, scale),
             color=joints, points=X[finite]),
        dict(ns=ns, id=1, type=LINE_LIST, scale=(scale / 3.0, 0.0, 0.0),
             color=lines, points=line_points),
    ]
    if names is not None:
        if len(names) != len(X):
            raise ValueError(f'{len(names)} names for {len(X)} keypoints')
        for k in np.flatnonzero(finite):
            specs.append(dict(ns=f'{ns}/names', id=2 + int(k), type=TEXT_VIEW_FACING,
                              scale=(0.0, 0.0, scale * 1.5), color=(1.0, 1.0, 1.0, 0.9),
                              points=np.zeros((0, 3)), text=str(names[k]),
                              position=X[k] + np.array([0.0, 0.0, scale * 1.5])))
    return specs


def frustum_corners(camera, depth):
    """(4, 3) world points of the image corners (pixel edges) at `depth` metres along the
    optical axis (pinhole, distortion ignored), in the order top-left, top-right,
    bottom-right, bottom-left."""
    w, h = camera.width, camera.height
    uv1 = np.array([[-0.5, -0.5, 1], [w - 0.5, -0.5, 1], [w - 0.5, h - 0.5, 1],
                    [-0.5, h - 0.5, 1]], np.float64)
    rays = uv1 @ np.linalg.inv(np.asarray(camera.K, np.float64)).T      # z = 1
    R, t = np.asarray(camera.R, np.float64), np.asarray(camera.t, np.float64)
    return (rays * depth - t) @ R          # R^T (x_cam - t), row-wise


def frustum_marker_specs(cameras, depth=0.2, ns='cameras', scale=0.005):
    """One LINE_LIST per camera (centre to the 4 corners, the 4 image edges at `depth`
    metres) with id 2i, and its name as text (id 2i + 1) at the centre; in metres whatever
    the cameras' unit (REP 103: these become messages)."""
    from monet_ros.geometry.units import rescale

    specs = []
    for i, cam in enumerate(rescale(cameras, 'm')):
        corners = frustum_corners(cam, depth)
        centre = np.asarray(cam.center, np.float64)
        segments = [(centre, c) for c in corners]
        segments += [(corners[k], corners[(k + 1) % 4]) for k in range(4)]
        specs.append(dict(ns=ns, id=2 * i, type=LINE_LIST, scale=(scale, 0.0, 0.0),
                          color=(0.9, 0.9, 0.2, 1.0),
                          points=np.array([p for seg in segments for p in seg])))
        specs.append(dict(ns=ns, id=2 * i + 1, type=TEXT_VIEW_FACING,
                          scale=(0.0, 0.0, 0.05), color=(0.9, 0.9, 0.2, 1.0),
                          points=np.zeros((0, 3)), text=cam.name, position=centre))
    return specs
