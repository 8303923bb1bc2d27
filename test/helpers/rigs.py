"""Random calibrated rigs looking at a common working volume, for geometry tests."""
import cv2
import numpy as np

from monet_ros.geometry import Camera


def look_at(center, target, up=(0.0, 0.0, 1.0)):
    """Rotation (world -> camera, OpenCV axes: z forward, y down) of a camera at `center`
    looking at `target`."""
    z = np.asarray(target, float) - np.asarray(center, float)
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-6:
        x = np.cross(z, (1.0, 0.0, 0.0))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z])


def random_camera(rng, name='cam', distortion=True, skew=0.0, radius=3.0, width=1280,
                  height=960, dist_len=5):
    """A camera on a sphere of `radius` around the origin, looking at it (roll jitter)."""
    direction = rng.normal(size=3)
    direction[2] = abs(direction[2]) * 0.5
    direction /= np.linalg.norm(direction)
    center = direction * radius
    R = look_at(center, rng.normal(scale=0.1, size=3))
    roll = cv2.Rodrigues(np.array([0.0, 0.0, rng.uniform(-0.3, 0.3)]))[0]
    R = roll @ R
    t = -R @ center
    f = rng.uniform(800, 1400)
    K = np.array([[f, skew, width / 2 + rng.uniform(-30, 30)],
                  [0.0, f * rng.uniform(0.97, 1.03), height / 2 + rng.uniform(-30, 30)],
                  [0.0, 0.0, 1.0]])
    dist = np.zeros(dist_len)
    if distortion and dist_len:
        scales = [0.1, 0.05, 0.002, 0.002, 0.02, 0.02, 0.01, 0.01, 0.002, 0.002, 0.002, 0.002]
        dist = rng.uniform(-1, 1, size=dist_len) * np.array(scales[:dist_len])
    return Camera(name=name, K=K, dist=dist, R=R, t=t, width=width, height=height)


def random_rig(rng, num_views, **kwargs):
    return [random_camera(rng, name=f'cam{i}', **kwargs) for i in range(num_views)]


def random_points(rng, n, scale=0.5):
    """(n, 3) points in the working volume around the origin."""
    return rng.uniform(-scale, scale, size=(n, 3))
