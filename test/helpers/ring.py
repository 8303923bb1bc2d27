"""A ring of cameras around a small working volume, for training/evaluation tests."""
import numpy as np

from helpers.rigs import look_at
from monet_ros.geometry import Camera


def ring_rig(num_views=6, radius=4.0, width=160, height=120, focal=150.0, dist=None,
             height_m=1.2, target=(0.0, 0.0, 1.0)):
    """Cameras on a circle around the origin looking at `target` (principal points vary)."""
    cameras = []
    for v in range(num_views):
        a = 2 * np.pi * v / num_views
        center = np.array([radius * np.cos(a), radius * np.sin(a), height_m + 0.3 * np.sin(3 * a)])
        R = look_at(center, target)
        K = np.array([[focal, 0, width / 2 - 0.5 + 3 * v], [0, focal, height / 2 - 0.5 - 2 * v],
                      [0, 0, 1]])
        cameras.append(Camera(f'cam{v}', K, dist if dist is not None else np.zeros(5), R,
                              -R @ center, width, height))
    return cameras


def random_points(n, seed=0, spread=0.4, center=(0.0, 0.0, 1.0)):
    """(n, 3) points uniformly in a cube of half-side `spread` around `center`."""
    rng = np.random.default_rng(seed)
    return np.asarray(center) + rng.uniform(-spread, spread, size=(n, 3))
