"""Initial extrinsics: pairwise camera poses from shared board views, chained over a
spanning tree (no ROS).

Each camera c sees board view f at pose T_cb (board -> camera, from PnP). Two cameras
seeing the same view give one estimate of their relative pose T_ji = T_jb T_ib^-1; the
estimate of a pair is the medoid rotation of its views' estimates (least summed angle to
the others, robust to a bad view) with the median translation. Cameras are joined by the
maximum spanning tree of the shared-view counts and posed from the root camera (the world
frame: the root's camera frame), so every camera is reached by the pairs with the most
shared views.
"""
import numpy as np


def pose_matrix(rvec, tvec):
    """4x4 [R | t] of a Rodrigues vector (3,) and a translation (3,)."""
    import cv2
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3))[0]
    T[:3, 3] = np.asarray(tvec, np.float64).reshape(3)
    return T


def invert(T):
    """Inverse of a rigid 4x4 transform (or a stack (..., 4, 4))."""
    out = np.zeros_like(T)
    R = T[..., :3, :3]
    out[..., :3, :3] = np.swapaxes(R, -1, -2)
    out[..., :3, 3] = -np.einsum('...ji,...j->...i', R, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def rotation_angle_deg(R):
    """Rotation angle (degrees) of rotation matrices (..., 3, 3)."""
    cos = (np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def robust_mean_pose(Ts):
    """One pose from estimates Ts (n, 4, 4): the medoid rotation, the median translation."""
    Ts = np.asarray(Ts)
    R = Ts[:, :3, :3]
    angles = rotation_angle_deg(np.einsum('aji,bjk->abik', R, R))     # (n, n)
    out = np.eye(4)
    out[:3, :3] = R[int(np.argmin(angles.sum(axis=1)))]
    out[:3, 3] = np.median(Ts[:, :3, 3], axis=0)
    return out


def shared_views(poses):
    """(C, C) counts of board views posed in both cameras; poses: list of {frame: T_cb}."""
    C = len(poses)
    counts = np.zeros((C, C), np.int64)
    for i in range(C):
        for j in range(i + 1, C):
            counts[i, j] = counts[j, i] = len(poses[i].keys() & poses[j].keys())
    return counts


def components(counts):
    """Connected groups of cameras (lists of indices, largest first) of a shared-view graph."""
    from scipy.sparse.csgraph import connected_components
    n, labels = connected_components(counts > 0, directed=False)
    groups = [list(np.flatnonzero(labels == k)) for k in range(n)]
    return sorted(groups, key=lambda g: (-len(g), g[0]))


def chain_extrinsics(poses, cameras):
    """World -> camera transforms (4, 4) of the cameras in `cameras` (a connected group).

    poses: per camera {frame: T_cb (4, 4)}. The root is the group's camera with the most
    shared views (its frame is the world frame). Returns (root, {camera: T_cw}, tree edges
    [(parent, child, shared views)])."""
    from scipy.sparse.csgraph import breadth_first_order, minimum_spanning_tree
    counts = shared_views(poses)
    sub = counts[np.ix_(cameras, cameras)]
    # maximum spanning tree of the counts: minimum of (big - count) over the existing edges
    weights = np.where(sub > 0, sub.max() + 1 - sub, 0).astype(np.float64)
    tree = minimum_spanning_tree(weights)
    tree = ((tree + tree.T) > 0).astype(np.int8)
    root_local = int(np.argmax(sub.sum(axis=1)))
    order, parents = breadth_first_order(tree, root_local, directed=False)
    root = cameras[root_local]
    extrinsics = {root: np.eye(4)}
    edges = []
    for local in order[1:]:
        child, parent = cameras[local], cameras[parents[local]]
        frames = sorted(poses[child].keys() & poses[parent].keys())
        relative = robust_mean_pose([poses[child][f] @ invert(poses[parent][f])
                                     for f in frames])
        extrinsics[child] = relative @ extrinsics[parent]
        edges.append((parent, child, len(frames)))
    return root, extrinsics, edges


def initial_board_poses(poses, extrinsics, num_frames):
    """Board -> world poses (F, 4, 4) (NaN for views no calibrated camera posed): from the
    camera that sees the view with the smallest board distance, T_wb = T_cw^-1 T_cb."""
    out = np.full((num_frames, 4, 4), np.nan)
    best = np.full(num_frames, np.inf)
    for c, T_cw in extrinsics.items():
        T_wc = invert(T_cw)
        for f, T_cb in poses[c].items():
            distance = np.linalg.norm(T_cb[:3, 3])
            if distance < best[f]:
                best[f] = distance
                out[f] = T_wc @ T_cb
    return out
