"""Small synthetic scenes for node tests, computed independently of the package code
(OpenCV projection, numpy Gaussians)."""
import cv2
import numpy as np

from monet_ros.geometry import Camera


def look_at(center, target, up=(0.0, 0.0, 1.0)):
    """World->camera (R, t) of an OpenCV camera (x right, y down, z forward) at `center`."""
    center, target = np.asarray(center, float), np.asarray(target, float)
    z = target - center
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ center


def ring_rig(count=4, radius=2.0, height=1.2, width=640, image_height=480, focal=600.0,
             target=(0.0, 0.0, 1.0), distortion=(0.02, -0.01, 0.0, 0.0, 0.0)):
    """`count` cameras on a circle of `radius` m around `target`, named cam0..."""
    cameras = []
    for i in range(count):
        angle = 2 * np.pi * i / count + 0.3
        center = (radius * np.cos(angle), radius * np.sin(angle), height + 0.1 * i)
        R, t = look_at(center, target)
        K = np.array([[focal, 0, width / 2 - 0.5 + 3 * i],
                      [0, focal * 1.01, image_height / 2 - 0.5], [0, 0, 1]])
        cameras.append(Camera(f'cam{i}', K, np.array(distortion), R, t, width, image_height,
                              topic=f'/cam{i}/image_raw'))
    return cameras


def cv2_project(camera, X):
    """OpenCV's projection (independent of Camera.project) of X (N, 3) -> (N, 2)."""
    rvec, _ = cv2.Rodrigues(camera.R)
    uv, _ = cv2.projectPoints(np.asarray(X, float).reshape(-1, 1, 3), rvec, camera.t,
                              camera.K, camera.dist)
    return uv.reshape(-1, 2)


def subject_box(uv, width, height, aspect, margin=0.25):
    """A crop box (x0, y0, x1, y1) in edge coordinates around points uv (N, 2), with the
    aspect ratio width/height of the heatmap grid."""
    lo, hi = np.nanmin(uv, axis=0), np.nanmax(uv, axis=0)
    centre = (lo + hi) / 2
    size = (hi - lo) * (1 + 2 * margin) + 20
    w = max(size[0], size[1] * aspect)
    h = w / aspect
    return (centre[0] - w / 2, centre[1] - h / 2, centre[0] + w / 2, centre[1] + h / 2)


def to_crop(uv, box, out_size):
    """Source pixels (N, 2) -> crop pixels (pixel centres on integers, edge-coordinate box)."""
    x0, y0, x1, y1 = box
    scale = np.array([out_size[0] / (x1 - x0), out_size[1] / (y1 - y0)])
    return (np.asarray(uv) + 0.5 - np.array([x0, y0])) * scale - 0.5


def gaussian_heatmaps(points, size, sigma=1.5, peak=1.0):
    """(C, h, w) float32 Gaussians of height `peak` (scalar or (C,)) at points (C, 2) (u, v);
    NaN points give empty maps."""
    h, w = size
    points = np.asarray(points, float)
    peak = np.broadcast_to(np.asarray(peak, float), (len(points),))
    v, u = np.mgrid[0:h, 0:w]
    d2 = (u[None] - points[:, 0, None, None]) ** 2 + (v[None] - points[:, 1, None, None]) ** 2
    maps = peak[:, None, None] * np.exp(-d2 / (2 * sigma ** 2))
    return np.nan_to_num(maps, nan=0.0).astype(np.float32)
