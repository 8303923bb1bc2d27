"""A calibrated synthetic rig: N cameras on a ring or a dome looking at the subject (no ROS).

World frame 'world', z up, metres. Cameras follow the OpenCV optical convention
(x right, y down, z forward) and are `monet_ros.geometry.Camera` objects named
cam0..cam{N-1} with image topics /camK/image_raw.
"""
from dataclasses import dataclass

import numpy as np

from monet_ros.geometry import Camera

LAYOUTS = ('ring', 'dome')
GOLDEN_RATIO = (5 ** 0.5 - 1) / 2
GOLDEN_ANGLE = np.pi * (3.0 - np.sqrt(5.0))


class RigConfigError(ValueError):
    """A rig parameter is invalid; the message names the field."""


def _check(condition, field, message):
    if not condition:
        raise RigConfigError(f'rig config: field {field!r}: {message}')


@dataclass(frozen=True)
class RigConfig:
    """Rig layout and intrinsics.

    num_cameras: N >= 2. layout: 'ring' (at camera_height, or alternately up to
    height_spread metres above and below it; evenly spread azimuths) or
    'dome' (a spiral over elevations dome_elevation_deg (min, max), golden-angle azimuths).
    radius: horizontal (ring) or spherical (dome) distance from the rig centre, metres.
    target: (x, y, z) point every camera looks at. image_width / image_height: pixels.
    hfov_deg: horizontal field of view (sets fx = fy = W / 2 / tan(hfov / 2)).
    distortion: OpenCV (k1, k2, p1, p2, k3), 1 to 5 values (missing ones are 0); must be
    monotonic over the image (checked). jitter: scale of the seeded perturbation of poses
    (position, aim, roll) and intrinsics (focal, principal point, distortion); 0 = none.
    """

    num_cameras: int = 8
    layout: str = 'ring'
    radius: float = 4.0
    camera_height: float = 1.6
    target: tuple = (0.0, 0.0, 0.9)
    image_width: int = 640
    image_height: int = 480
    hfov_deg: float = 60.0
    distortion: tuple = (-0.08, 0.02, 0.0, 0.0, 0.0)
    dome_elevation_deg: tuple = (10.0, 55.0)
    jitter: float = 1.0
    height_spread: float = 0.0

    def __post_init__(self):
        for key in ('num_cameras', 'image_width', 'image_height'):
            value = getattr(self, key)
            _check(isinstance(value, (int, np.integer)) and not isinstance(value, bool),
                   key, f'must be an integer, got {value!r}')
        _check(2 <= self.num_cameras <= 64, 'num_cameras',
               f'must be in 2..64, got {self.num_cameras}')
        _check(self.layout in LAYOUTS, 'layout', f'must be one of {LAYOUTS}, got {self.layout!r}')
        _check(self.radius > 0 and np.isfinite(self.radius), 'radius',
               f'must be a positive number, got {self.radius!r}')
        _check(np.isfinite(self.camera_height), 'camera_height', 'must be finite')
        target = np.asarray(self.target, dtype=float)
        _check(target.shape == (3,) and np.all(np.isfinite(target)), 'target',
               f'must be 3 finite numbers, got {self.target!r}')
        _check(16 <= self.image_width <= 8192, 'image_width',
               f'must be in 16..8192, got {self.image_width}')
        _check(16 <= self.image_height <= 8192, 'image_height',
               f'must be in 16..8192, got {self.image_height}')
        _check(10.0 <= self.hfov_deg <= 150.0, 'hfov_deg',
               f'must be in 10..150 degrees, got {self.hfov_deg}')
        dist = np.asarray(self.distortion, dtype=float).ravel()
        _check(1 <= dist.size <= 5 and np.all(np.isfinite(dist)), 'distortion',
               f'must be 1 to 5 finite numbers (k1, k2, p1, p2, k3), got {self.distortion!r}')
        object.__setattr__(self, 'distortion', tuple(float(d) for d in dist))
        object.__setattr__(self, 'target', tuple(float(v) for v in target))
        lo, hi = (float(v) for v in self.dome_elevation_deg)
        _check(-30.0 <= lo <= hi <= 85.0, 'dome_elevation_deg',
               f'must be (min, max) with -30 <= min <= max <= 85, got {self.dome_elevation_deg}')
        _check(0.0 <= self.jitter <= 5.0, 'jitter', f'must be in 0..5, got {self.jitter}')
        half = 1.25 * np.array([self.image_width, self.image_height]) / 2.0 / self.focal
        _check(distortion_one_to_one(self.distortion5, *half)
               and distortion_invertible(self.distortion5, self.image_width,
                                         self.image_height, self.focal), 'distortion',
               f'{self.distortion} folds over inside the image (the distortion map is not '
               'one-to-one there); use smaller coefficients')
        _check(np.isfinite(self.height_spread) and 0.0 <= self.height_spread <= 10.0,
               'height_spread', f'must be in 0..10 metres, got {self.height_spread}')

    @property
    def distortion5(self):
        """(5,) k1, k2, p1, p2, k3."""
        d = np.zeros(5)
        d[:len(self.distortion)] = self.distortion
        return d

    @property
    def focal(self):
        return self.image_width / 2.0 / np.tan(np.radians(self.hfov_deg) / 2.0)

    @property
    def max_normalized_radius(self):
        """Normalised radius of the image corner (ideal pinhole)."""
        return float(np.hypot(self.image_width / 2.0, self.image_height / 2.0) / self.focal)


def distortion_one_to_one(dist5, x_max, y_max, samples=129):
    """True when the OpenCV distortion map (k1, k2, p1, p2, k3; radial and tangential) keeps
    its Jacobian determinant above 0.05 (no fold, no collapse) and finite on the normalised
    rectangle |x| <= x_max, |y| <= y_max."""
    k1, k2, p1, p2, k3 = (float(v) for v in dist5)
    x, y = np.meshgrid(np.linspace(-x_max, x_max, samples), np.linspace(-y_max, y_max, samples))
    with np.errstate(all='ignore'):
        r2 = x * x + y * y
        radial = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        dx, dy = x[0, 1] - x[0, 0], y[1, 0] - y[0, 0]
        dxd_dy, dxd_dx = np.gradient(xd, dy, dx)
        dyd_dy, dyd_dx = np.gradient(yd, dy, dx)
        det = dxd_dx * dyd_dy - dxd_dy * dyd_dx
        return bool(np.all(np.isfinite(det)) and np.all(det > 0.05)
                    and radial_monotonic(dist5, float(np.hypot(x_max, y_max))))


def distortion_invertible(dist5, width, height, focal, samples=33):
    """True when every pixel of a (width x height) image with this focal length and
    distortion undistorts (Camera.undistort_points converges) and distorts back to itself
    within 0.01 px - the renderer casts a viewing ray through every pixel."""
    K = np.array([[focal, 0, width / 2.0], [0, focal, height / 2.0], [0, 0, 1]])
    camera = Camera(name='check', K=K, dist=np.asarray(dist5, float), R=np.eye(3),
                    t=np.zeros(3), width=int(width), height=int(height))
    u, v = np.meshgrid(np.linspace(-0.5, width - 0.5, samples),
                       np.linspace(-0.5, height - 0.5, samples))
    uv = np.stack([u.ravel(), v.ravel()], axis=1)
    with np.errstate(all='ignore'):
        ideal = camera.undistort_points(uv)
        if not np.all(np.isfinite(ideal)):
            return False
        rays = np.concatenate([camera.pixels_to_normalized(ideal), np.ones((len(uv), 1))], 1)
        back = camera.project(rays)
    return bool(np.all(np.isfinite(back)) and np.abs(back - uv).max() < 0.01)


def radial_monotonic(dist5, r_max, samples=512):
    """True when r (1 + k1 r^2 + k2 r^4 + k3 r^6) increases on [0, r_max]."""
    k1, k2, _, _, k3 = dist5
    r = np.linspace(0.0, r_max, samples)
    r2 = r * r
    derivative = 1 + 3 * k1 * r2 + 5 * k2 * r2 ** 2 + 7 * k3 * r2 ** 3
    return bool(np.all(derivative > 0.05))


def look_at(center, target, roll=0.0):
    """World -> camera rotation (3, 3) of a camera at `center` looking at `target`, world z up
    (image y points down, towards -z), rotated by `roll` radians about the optical axis."""
    center = np.asarray(center, dtype=float)
    forward = np.asarray(target, dtype=float) - center
    forward /= np.linalg.norm(forward)
    up = np.array([0.0, 0.0, 1.0])
    right = np.cross(forward, up)
    if np.linalg.norm(right) < 1e-9:                  # looking straight up/down
        right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    R = np.stack([right, down, forward])
    c, s = np.cos(roll), np.sin(roll)
    roll_matrix = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return roll_matrix @ R


def camera_centers(config, rng):
    """(N, 3) nominal camera centres plus seeded jitter."""
    n = config.num_cameras
    k = np.arange(n)
    azimuth = 2 * np.pi * k / n + rng.uniform(-1, 1, n) * 0.05 * config.jitter
    if config.layout == 'ring':
        radius = config.radius * (1 + rng.uniform(-1, 1, n) * 0.03 * config.jitter)
        z = config.camera_height + rng.uniform(-1, 1, n) * 0.1 * config.jitter
        # non-coplanar ring: alternately above and below, 0.5..1 x height_spread (no draw
        # from rng, so height_spread = 0 keeps every byte of a seed's rig)
        z = z + config.height_spread * (-1.0) ** k * (0.5 + 0.5 * ((k * GOLDEN_RATIO) % 1))
        return np.stack([radius * np.cos(azimuth), radius * np.sin(azimuth), z], axis=1)
    lo, hi = np.radians(config.dome_elevation_deg)
    # spiral: elevation climbs with k, azimuth advances by the golden angle
    elevation = lo + (hi - lo) * (k + 0.5) / n + rng.uniform(-1, 1, n) * 0.02 * config.jitter
    azimuth = k * GOLDEN_ANGLE + rng.uniform(-1, 1, n) * 0.05 * config.jitter
    radius = config.radius * (1 + rng.uniform(-1, 1, n) * 0.03 * config.jitter)
    flat = radius * np.cos(elevation)
    return np.stack([flat * np.cos(azimuth), flat * np.sin(azimuth),
                     radius * np.sin(elevation)], axis=1)


def make_rig(config, seed=0):
    """list[Camera] cam0..cam{N-1} for a RigConfig, deterministic for `seed`."""
    rng = np.random.default_rng([int(seed), 0x5249])       # 'RI': rig stream
    centers = camera_centers(config, rng)
    n = config.num_cameras
    j = config.jitter
    aim = np.asarray(config.target) + rng.uniform(-1, 1, (n, 3)) * 0.05 * j
    roll = rng.uniform(-1, 1, n) * np.radians(2.0) * j
    focal = config.focal * (1 + rng.uniform(-1, 1, (n, 2)) * [0.03, 0.03] * j)
    principal = (np.array([(config.image_width - 1) / 2.0, (config.image_height - 1) / 2.0])
                 + rng.uniform(-1, 1, (n, 2)) * 0.01
                 * np.array([config.image_width, config.image_height]) * j)
    dist = config.distortion5 * (1 + rng.uniform(-1, 1, (n, 5)) * 0.1 * j)
    cameras = []
    for i in range(n):
        R = look_at(centers[i], aim[i], roll[i])
        K = np.array([[focal[i, 0], 0.0, principal[i, 0]],
                      [0.0, focal[i, 1], principal[i, 1]],
                      [0.0, 0.0, 1.0]])
        cameras.append(Camera(name=f'cam{i}', K=K, dist=dist[i], R=R, t=-R @ centers[i],
                              width=config.image_width, height=config.image_height,
                              topic=f'/cam{i}/image_raw'))
    return cameras
