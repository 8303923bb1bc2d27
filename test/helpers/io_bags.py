"""Shared helpers for the io tests: a random Camera and small synthetic bags."""
import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from monet_ros.geometry import Camera


def make_camera(name='cam0', seed=0, dist=(0.1, -0.05, 0.001, 0.002, 0.01), size=(640, 480)):
    """A camera with a random pose (seeded) and fixed intrinsics."""
    rng = np.random.default_rng(seed)
    R = Rotation.from_rotvec(rng.normal(size=3)).as_matrix()
    K = np.array([[500.0 + seed, 0, size[0] / 2 + 0.5], [0, 505.0, size[1] / 2 + 0.25],
                  [0, 0, 1]])
    return Camera(name=name, K=K, dist=np.array(dist), R=R, t=rng.normal(size=3),
                  width=size[0], height=size[1])


def smooth_images(rng, n, h, w):
    """(n, h, w, 3) uint8 smooth random images (upscaled noise)."""
    out = np.empty((n, h, w, 3), np.uint8)
    for i in range(n):
        small = rng.integers(0, 256, (max(h // 16, 2), max(w // 16, 2), 3)).astype(np.uint8)
        out[i] = cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)
    return out


def write_rig_bag(path, cams, t0, instants, chunk_size=None):
    """A rosbag2 folder at `path`: /tf_static of `cams` at t0, then per instant k (t0 + k
    ns) each camera's camera_info and a black rgb8 image_raw (frames <name>_optical)."""
    from monet_ros.io import BagWriter
    options = {} if chunk_size is None else {'chunk_size': chunk_size}
    with BagWriter(path, **options) as bag:
        bag.write_tf_static(t0, cams)
        for k in range(instants):
            for cam in cams:
                bag.write_camera_info(f'/{cam.name}/camera_info', t0 + k, cam,
                                      f'{cam.name}_optical')
                bag.write_image(f'/{cam.name}/image_raw', t0 + k,
                                np.zeros((cam.height, cam.width, 3), np.uint8),
                                f'{cam.name}_optical')
