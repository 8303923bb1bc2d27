"""Small procedural rigs and scenes for training/evaluation tests (no files)."""
import numpy as np

from monet_ros.geometry import Camera


def look_at(center, target=(0.0, 0.0, 1.0), up=(0.0, 0.0, 1.0)):
    """(R, t) of a camera at `center` looking at `target` (OpenCV axes: y down)."""
    center = np.asarray(center, dtype=np.float64)
    z = np.asarray(target, dtype=np.float64) - center
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ center


def ring_rig(num_views=6, radius=4.0, width=160, height=120, focal=150.0, dist=None,
             height_m=1.2, jitter=0.0, seed=0):
    """Cameras on a circle around the origin looking at (0, 0, 1)."""
    rng = np.random.default_rng(seed)
    cameras = []
    for v in range(num_views):
        a = 2 * np.pi * v / num_views + jitter * rng.uniform(-1, 1)
        center = (radius * np.cos(a), radius * np.sin(a), height_m + 0.3 * np.sin(3 * a))
        R, t = look_at(center)
        K = np.array([[focal, 0, width / 2 - 0.5 + 3 * v], [0, focal, height / 2 - 0.5 - 2 * v],
                      [0, 0, 1]])
        cameras.append(Camera(f'cam{v}', K, dist if dist is not None else np.zeros(5), R, t,
                              width, height))
    return cameras


def random_points(n, seed=0, spread=0.4, center=(0.0, 0.0, 1.0)):
    rng = np.random.default_rng(seed)
    return np.asarray(center) + rng.uniform(-spread, spread, size=(n, 3))
