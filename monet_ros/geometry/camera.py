"""Pinhole camera with the OpenCV distortion model, and the crop/scale virtual camera.

Convention (DESIGN.md): x_pixel ~ K (R X + t), world -> camera; pixel (u, v) = column u,
row v, pixel centres on integers; distortion D in OpenCV order
(k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4]]]).
"""
from dataclasses import dataclass, field, replace

import numpy as np

from monet_ros.geometry.units import UNITS, per_metre, rig_units
from monet_ros.jit import kernel

# Accepted distortion vector lengths (OpenCV: 4, 5, 8, 12; 14 = tilted sensor, unsupported).
DIST_LENGTHS = (0, 4, 5, 8, 12)
_ROTATION_TOL = 1e-6


MAX_K = 1e7   # largest |K| entry in pixels (focal lengths of real lenses are < 1e5 px)


class CameraError(ValueError):
    """A camera parameter is invalid; `.field` names the offending field."""

    def __init__(self, camera, field_name, message):
        self.camera = camera
        self.field = field_name
        self.message = message
        super().__init__(f'camera {camera!r}: field {field_name!r}: {message}')

    def __reduce__(self):
        # raised in a worker process: it must unpickle in the parent
        return type(self), (self.camera, self.field, self.message)


def _matrix(value, shape, camera, field_name):
    try:
        array = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise CameraError(camera, field_name, f'not numeric ({exc})') from None
    if array.size == int(np.prod(shape)) and array.ndim <= 2 and len(shape) == 1:
        array = array.reshape(shape)
    if array.shape != shape:
        raise CameraError(camera, field_name, f'expected shape {shape}, got {array.shape}')
    if not np.all(np.isfinite(array)):
        raise CameraError(camera, field_name, 'contains NaN or infinity')
    array.setflags(write=False)
    return array


def crop_transform(box, out_size):
    """3x3 affine S of a crop + scale: original pixels -> crop pixels.

    box: (x0, y0, x1, y1) in pixel-EDGE coordinates (the full W x H image is (0, 0, W, H));
    out_size: (W_out, H_out). Pixel centres are integers, so
    u' = (u + 0.5 - x0) * W_out / (x1 - x0) - 0.5 (same for v with y0, y1, H_out).
    `cv2.warpAffine(image, S[:2], out_size)` produces exactly this crop.
    """
    x0, y0, x1, y1 = (float(v) for v in np.asarray(box, dtype=np.float64).reshape(4))
    w_out, h_out = (float(v) for v in out_size)
    if not (x1 > x0 and y1 > y0):
        raise ValueError(f'crop box {tuple(box)} must have x1 > x0 and y1 > y0')
    if not (w_out > 0 and h_out > 0):
        raise ValueError(f'crop out_size {tuple(out_size)} must be positive (W, H)')
    sx = w_out / (x1 - x0)
    sy = h_out / (y1 - y0)
    return np.array([[sx, 0.0, (0.5 - x0) * sx - 0.5],
                     [0.0, sy, (0.5 - y0) * sy - 0.5],
                     [0.0, 0.0, 1.0]])


def _model_terms(d12):
    """(12 coefficients broadcastable against points, rational?, thin prism?, tangential?)
    of distortion vectors d12 (..., 12): the rational, prism and tangential terms are skipped
    when all zero (stack_cameras keeps a rig's under 'model')."""
    d12 = np.asarray(d12, np.float64)
    coeffs = tuple(np.moveaxis(d12, -1, 0)[..., None]) if d12.ndim > 1 else tuple(d12)
    return (coeffs, bool(d12[..., 5:8].any()), bool(d12[..., 8:].any()),
            bool(d12[..., 2:4].any()))


def _distort(terms, x, y):
    """Distorted normalised (x_d, y_d) of ideal (x, y) by the OpenCV model; terms from
    _model_terms."""
    (k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4), rational, prism, tangential = terms
    r2 = x * x + y * y
    r4 = r2 * r2
    r6 = r4 * r2
    radial = 1 + k1 * r2 + k2 * r4 + k3 * r6
    if rational:
        radial = radial / (1 + k4 * r2 + k5 * r4 + k6 * r6)
    xd = x * radial
    yd = y * radial
    if tangential:
        xy2 = 2 * x * y
        xd = xd + (p1 * xy2 + p2 * (r2 + 2 * x * x))
        yd = yd + (p1 * (r2 + 2 * y * y) + p2 * xy2)
    if prism:
        xd = xd + (s1 * r2 + s2 * r4)
        yd = yd + (s3 * r2 + s4 * r4)
    return xd, yd


def _undistort_newton(d12, x0, y0, iterations, tol, terms=None):
    """Ideal normalised (x, y) with distort(x, y) = (x0, y0): Newton's method on the OpenCV
    model with its analytic 2x2 Jacobian, all points at once (d12: (12,) or, for V
    cameras, (V, 12) against x0, y0 (V, N); terms: _model_terms(d12) when known). Stops
    after `iterations` (>= 1) or when every finite step is <= tol; NaN where a point has
    not converged (its last step above tol) and the last iterate before the final step
    misses (x0, y0) by more than 1e-9 (relative), or where it lies past a fold of the
    model (Jacobian determinant <= 0): no unique inverse there."""
    terms = terms or _model_terms(d12)
    (k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4), rational, prism, tangential = terms
    if not (rational or prism or tangential):
        return _radial_undistort_normalized(k1, k2, k3, x0, y0, iterations, tol)
    # twice the derivatives of the radial polynomials by r2
    dk1, dk2, dk3 = 2 * k1, 4 * k2, 6 * k3
    if rational:
        dk4, dk5, dk6 = 2 * k4, 4 * k5, 6 * k6

    def model(x, y):
        """Residual of distort(x, y) - (x0, y0) and the Jacobian (xx, xy, yx, yy)."""
        xx, yy, xy = x * x, y * y, x * y
        r2 = xx + yy
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        slope = dk1 + r2 * (dk2 + r2 * dk3)  # 2 d radial / d r2
        if rational:
            den = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
            slope = (slope - radial * (dk4 + r2 * (dk5 + r2 * dk6)) / den) / den
            radial = radial / den
        jxx = radial + xx * slope
        jyy = radial + yy * slope
        jxy = xy * slope
        if tangential:
            xy2 = 2 * xy
            fx = x * radial + p1 * xy2 + p2 * (r2 + 2 * xx) - x0
            fy = y * radial + p1 * (r2 + 2 * yy) + p2 * xy2 - y0
            jxx = jxx + (2 * p1 * y + 6 * p2 * x)
            jyy = jyy + (6 * p1 * y + 2 * p2 * x)
            jxy = jxy + 2 * (p1 * x + p2 * y)
        else:
            fx = x * radial - x0
            fy = y * radial - y0
        jyx = jxy
        if prism:
            fx = fx + r2 * (s1 + s2 * r2)
            fy = fy + r2 * (s3 + s4 * r2)
            gx = 2 * (s1 + 2 * s2 * r2)
            gy = 2 * (s3 + 2 * s4 * r2)
            jxx, jxy = jxx + gx * x, jxy + gx * y
            jyx, jyy = jyx + gy * x, jyy + gy * y
        return fx, fy, jxx, jxy, jyx, jyy

    x, y = x0, y0
    with np.errstate(all='ignore'):
        for _ in range(max(1, iterations)):
            fx, fy, jxx, jxy, jyx, jyy = model(x, y)
            det = jxx * jyy - jxy * jyx
            step_x = (jyy * fx - jxy * fy) / det
            step_y = (jxx * fy - jyx * fx) / det
            x = x - step_x
            y = y - step_y
            change = np.maximum(np.abs(step_x), np.abs(step_y))
            if not ((change > tol) & (change < np.inf)).any():  # every finite step <= tol
                break
        # converged (the last step <= tol: a caller's loose tol is not a failure) or the
        # residual of the last evaluated iterate within 1e-9 (the final step only refines it
        # further: no extra evaluation of the model), and its Jacobian not folded
        failed = ~(((change <= tol)
                    | (np.hypot(fx, fy) <= 1e-9 * np.maximum(1.0, np.hypot(x0, y0))))
                   & (det > 0))
    return np.where(failed, np.nan, x), np.where(failed, np.nan, y)


@kernel(example=lambda: (np.zeros((1, 1, 2)), np.eye(3)[None], np.zeros((1, 3)), 20, 1e-15))
def _radial_undistort(uv, K, k, iterations, tol):
    """The undistortion of a radial lens model (k1, k2, k3 only: most calibrations) of V
    cameras: uv (V, n, 2) observed pixels of camera v (float64), K (V, 3, 3), k (V, 3)
    its (k1, k2, k3) -> ideal pixels (V, n, 2) of the same K, NaN where the inversion fails
    (and for NaN input). Compiled (monet_ros.jit): a loop over points.

    The distortion moves a point along its ray from the principal point, so the 2D inverse
    is the 1D one of the normalised radius, r radial(r^2) = r0, by Newton's method from
    r0, and the ideal point is c + (r / r0) (uv - c). These are the 2D Newton iterates of
    _undistort_newton in exact arithmetic (a 2D step of a radial model stays on the ray)
    with its stopping rule per point (`iterations` at most, or a step <= tol or not
    finite). Failures: not converged (a last step above tol) with a residual above 1e-9
    (relative) at the last evaluated iterate, or a root past the fold: the 2D Jacobian's
    eigenvalues along and across the ray (along, radial) must both be > 0, i.e. the root
    on the branch that starts at the centre (the 2D solve asks only for their product, and
    past the fold can land on the opposite ray where both are negative: a point the model
    maps there, but from behind its fold).
    Inside the fold the iteration from r0 is monotone (f = r radial - r0 is concave for
    barrel, convex for pincushion distortion), so it finds that branch's root."""
    V, n = uv.shape[0], uv.shape[1]
    out = np.empty((V, n, 2))
    for c in range(V):
        fx, skew, cx, fy, cy = K[c, 0, 0], K[c, 0, 1], K[c, 0, 2], K[c, 1, 1], K[c, 1, 2]
        k1, k2, k3 = k[c, 0], k[c, 1], k[c, 2]
        a1, a2, a3 = 3 * k1, 5 * k2, 7 * k3     # d (r radial(r^2)) / dr = 1 + r2 (a1 + ...)
        for i in range(n):
            du, dv = uv[c, i, 0] - cx, uv[c, i, 1] - cy
            y0 = dv / fy
            x0 = (du - skew * y0) / fx
            r0 = np.sqrt(x0 * x0 + y0 * y0)
            r, f, radial, along, step = r0, np.nan, np.nan, np.nan, np.nan
            for _ in range(max(1, iterations)):
                r2 = r * r
                radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
                along = 1 + r2 * (a1 + r2 * (a2 + r2 * a3))
                f = r * radial - r0
                step = f / along
                r = r - step
                if not (tol < abs(step) < np.inf):  # converged, or no finite step
                    break
            # converged (the last step <= tol) or the residual of the last evaluated iterate
            # within 1e-9, and its Jacobian on the branch from the centre (_undistort_newton)
            if ((abs(step) <= tol or abs(f) <= 1e-9 * max(1.0, r0))
                    and radial > 0 and along > 0):
                scale = r / r0 if r0 > 0 else 1.0
                out[c, i, 0] = cx + scale * du
                out[c, i, 1] = cy + scale * dv
            else:
                out[c, i, 0] = np.nan
                out[c, i, 1] = np.nan
    return out


def _radial_undistort_normalized(k1, k2, k3, x0, y0, iterations, tol):
    """_radial_undistort of distorted normalised points (x0, y0) (any shape; k1, k2, k3
    scalars or broadcastable to it) -> the ideal (x, y) of that shape (K = identity: one
    camera, or one per point where the coefficients are arrays)."""
    x0, y0 = np.broadcast_arrays(x0, y0)
    if all(np.ndim(k) == 0 for k in (k1, k2, k3)):
        shape = x0.shape
        uv = np.stack([x0, y0], axis=-1).reshape(1, -1, 2)
        K, k = np.eye(3)[None], np.array([[k1, k2, k3]], np.float64)
    else:  # a camera per point
        x0, y0, k1, k2, k3 = np.broadcast_arrays(x0, y0, k1, k2, k3)
        shape = x0.shape
        uv = np.stack([x0, y0], axis=-1).reshape(-1, 1, 2)
        K = np.tile(np.eye(3), (len(uv), 1, 1))
        k = np.stack([k1, k2, k3], axis=-1).reshape(-1, 3)
    out = _radial_undistort(uv, K, k, iterations, tol).reshape(shape + (2,))
    return out[..., 0], out[..., 1]


@dataclass(frozen=True, eq=False)
class Camera:
    """A calibrated camera: x_pixel ~ K (R X + t) with OpenCV lens distortion `dist`.

    Arrays are float64 and read-only: K (3, 3) upper triangular (skew K[0, 1] allowed,
    positive focal lengths, K[2] = [0, 0, 1]), dist (0 | 4 | 5 | 8 | 12,), R (3, 3) rotation,
    t (3,). width, height in pixels; topic is the image topic (optional); units is the
    rig's length unit, that of t and of the world points ('m', 'cm' or 'mm';
    geometry.units).
    """

    name: str
    K: np.ndarray
    dist: np.ndarray
    R: np.ndarray
    t: np.ndarray
    width: int
    height: int
    topic: str | None = None
    units: str = 'm'
    _d12: np.ndarray = field(init=False, repr=False)
    _P: np.ndarray = field(init=False, repr=False)
    _distorted: bool = field(init=False, repr=False)

    def __post_init__(self):
        name = self.name
        if not isinstance(name, str) or not name:
            raise CameraError(name, 'name', 'must be a non-empty string')
        K = _matrix(self.K, (3, 3), name, 'K')
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise CameraError(name, 'K', f'focal lengths must be positive, got fx={K[0, 0]}, '
                              f'fy={K[1, 1]}')
        if np.abs(K).max() > MAX_K:
            raise CameraError(name, 'K', f'values beyond {MAX_K:g} pixels (largest '
                              f'{np.abs(K).max():.3g}): not a real camera')
        if K[1, 0] != 0 or not np.array_equal(K[2], [0.0, 0.0, 1.0]):
            raise CameraError(name, 'K', 'must be upper triangular with last row [0, 0, 1]')
        dist = np.array(self.dist if self.dist is not None else [], dtype=np.float64).ravel()
        if dist.size not in DIST_LENGTHS:
            raise CameraError(name, 'dist', f'length must be one of {DIST_LENGTHS} '
                              f'(OpenCV order k1 k2 p1 p2 k3 k4 k5 k6 s1..s4), got {dist.size}')
        if not np.all(np.isfinite(dist)):
            raise CameraError(name, 'dist', 'contains NaN or infinity')
        dist.setflags(write=False)
        R = _matrix(self.R, (3, 3), name, 'R')
        ortho = np.abs(R @ R.T - np.eye(3)).max()
        if ortho > _ROTATION_TOL or np.linalg.det(R) <= 0:
            raise CameraError(name, 'R', f'not a rotation (|R R^T - I| = {ortho:.3g}, '
                              f'det = {np.linalg.det(R):.6g})')
        t = _matrix(self.t, (3,), name, 't')
        for key in ('width', 'height'):
            value = getattr(self, key)
            if isinstance(value, bool) or int(value) != value or value <= 0:
                raise CameraError(name, key, f'must be a positive integer, got {value!r}')
            object.__setattr__(self, key, int(value))
        if self.topic is not None and not isinstance(self.topic, str):
            raise CameraError(name, 'topic', f'must be a string or None, got {self.topic!r}')
        if self.units not in UNITS:
            raise CameraError(name, 'units', f'must be one of {UNITS}, got {self.units!r}')
        d12 = np.zeros(12)
        d12[:dist.size] = dist
        P = K @ np.hstack([R, t[:, None]])
        P.setflags(write=False)
        for key, value in (('K', K), ('dist', dist), ('R', R), ('t', t), ('_d12', d12),
                           ('_P', P)):
            object.__setattr__(self, key, value)
        object.__setattr__(self, '_distorted', bool(np.any(dist != 0)))

    def __eq__(self, other):
        if not isinstance(other, Camera):
            return NotImplemented
        return (self.name == other.name and self.width == other.width
                and self.height == other.height and self.topic == other.topic
                and self.units == other.units
                and all(np.array_equal(getattr(self, k), getattr(other, k))
                        for k in ('K', 'dist', 'R', 't')))

    __hash__ = None

    @property
    def P(self):
        """(3, 4) projection matrix K [R | t] (ideal pinhole, no distortion; read-only)."""
        return self._P

    @property
    def center(self):
        """(3,) camera centre in world coordinates, -R^T t."""
        return -self.R.T @ self.t

    @property
    def has_distortion(self):
        return self._distorted

    def replace(self, **changes):
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)

    def without_distortion(self):
        """The same camera with dist = () (ideal pinhole)."""
        return replace(self, dist=np.zeros(0))

    def to_camera(self, X):
        """World points (..., 3) -> camera coordinates (..., 3)."""
        X = np.asarray(X, dtype=np.float64)
        return X @ self.R.T + self.t

    def distort_normalized(self, xy):
        """Ideal normalised coordinates (..., 2) -> distorted normalised coordinates."""
        xy = np.asarray(xy, dtype=np.float64)
        if not self.has_distortion:
            return xy.copy()
        return np.stack(_distort(_model_terms(self._d12), xy[..., 0], xy[..., 1]), axis=-1)

    def normalized_to_pixels(self, xy):
        """Normalised image coordinates (..., 2) -> pixels through K (honours skew)."""
        xy = np.asarray(xy, dtype=np.float64)
        K = self.K
        u = K[0, 0] * xy[..., 0] + K[0, 1] * xy[..., 1] + K[0, 2]
        v = K[1, 1] * xy[..., 1] + K[1, 2]
        return np.stack([u, v], axis=-1)

    def pixels_to_normalized(self, uv):
        """Pixels (..., 2) -> normalised image coordinates through K^-1 (honours skew)."""
        uv = np.asarray(uv, dtype=np.float64)
        K = self.K
        y = (uv[..., 1] - K[1, 2]) / K[1, 1]
        x = (uv[..., 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
        return np.stack([x, y], axis=-1)

    def project(self, X):
        """World points X (N, 3) -> pixels (N, 2) with lens distortion (cv2.projectPoints
        model, plus K's skew). Points at depth 0 give inf/NaN; no visibility test.
        """
        Xc = self.to_camera(X)
        xy = Xc[..., :2] / Xc[..., 2:3]
        return self.normalized_to_pixels(self.distort_normalized(xy))

    def undistort_normalized(self, xy, iterations=20, tol=1e-15):
        """Distorted normalised coordinates (..., 2) -> ideal ones: the inverse of the
        distortion model by Newton's method (analytic Jacobian, all points at once; the
        answer of cv2.undistortPoints iterated to convergence). NaN where the model has no
        unique inverse (a point outside its invertible region) and for NaN input."""
        xy0 = np.asarray(xy, dtype=np.float64)
        if not self.has_distortion:
            return xy0.copy()
        x, y = _undistort_newton(self._d12, xy0[..., 0], xy0[..., 1], iterations, tol)
        return np.stack([x, y], axis=-1)

    def undistort_points(self, uv):
        """Observed pixels uv (N, 2) -> ideal pinhole pixels (N, 2) of the same K.

        Inverse of `project`'s distortion (undistort_normalized); honours the skew in K.
        NaN rows stay NaN; points where the inversion fails become NaN. Without distortion
        the input is returned (as a copy).
        """
        uv = np.asarray(uv, dtype=np.float64)
        if not self.has_distortion:
            return uv.copy()
        return self.normalized_to_pixels(self.undistort_normalized(self.pixels_to_normalized(uv)))

    def crop(self, box, out_size):
        """Virtual camera of a crop/scale of this camera's image: K' = S K with
        S = crop_transform(box, out_size); same dist, R, t; (width, height) = out_size."""
        S = crop_transform(box, out_size)
        w_out, h_out = out_size
        return replace(self, K=S @ self.K, width=int(w_out), height=int(h_out))


_STACK_CACHE = {}  # id-tuple -> (cameras tuple, stacked dict); cameras are immutable


def stack_cameras(cameras):
    """Stacked parameters of a rig: dict of K (V, 3, 3), R (V, 3, 3), t (V, 3), P (V, 3, 4),
    Rt (V, 3, 4) = [R | t], K_inv (V, 3, 3), d12 (V, 12) (distortion padded to 12
    coefficients), model (d12 as _model_terms gives it), per_metre (float: the cameras'
    length unit per metre, geometry.units; ValueError when their units differ).
    The last few rigs are cached (Cameras are immutable): do not modify the arrays."""
    cameras = tuple(cameras)
    key = tuple(map(id, cameras))
    hit = _STACK_CACHE.get(key)
    if hit is not None and hit[0] == cameras:  # Camera has eq=False: the same objects
        return hit[1]
    stacked = {'K': np.stack([c.K for c in cameras]), 'R': np.stack([c.R for c in cameras]),
               't': np.stack([c.t for c in cameras]), 'P': np.stack([c.P for c in cameras]),
               'd12': np.stack([c._d12 for c in cameras])}
    stacked['Rt'] = np.concatenate([stacked['R'], stacked['t'][:, :, None]], axis=-1)
    stacked['K_inv'] = np.linalg.inv(stacked['K'])
    for array in stacked.values():
        array.setflags(write=False)
    stacked['model'] = _model_terms(stacked['d12'])  # (coefficients, flags) of _distort
    stacked['per_metre'] = per_metre(rig_units(cameras))
    if len(_STACK_CACHE) >= 16:
        _STACK_CACHE.pop(next(iter(_STACK_CACHE)))
    _STACK_CACHE[key] = (cameras, stacked)
    return stacked


def _apply_views(M, X):
    """X (..., N, 3) through per-view (V, 3, 4) matrices -> (..., V, N, 3), one GEMM."""
    V = M.shape[0]
    lead, N = X.shape[:-2], X.shape[-2]
    flat = X.reshape(-1, 3)
    out = flat @ M[:, :, :3].reshape(V * 3, 3).T + M[:, :, 3].reshape(V * 3)  # (M, 3V)
    return out.reshape(*lead, N, V, 3).swapaxes(-2, -3)


def project_views(cameras, X):
    """Project points into every camera of a rig at once (same model as Camera.project).

    X: (..., N, 3) world points (leading dims are batch); returns (..., V, N, 2) pixels,
    non-finite (no warning) for a point in a camera's focal plane (z = 0), which has no
    image; callers count such points as not projected.
    `cameras` is a list of Camera or the dict of stack_cameras.
    """
    with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
        return _project_views(cameras, X)


def _project_views(cameras, X):
    return np.stack(project_uv(cameras, X), axis=-1)


def project_uv(cameras, X):
    """project_views' pixels as two arrays (u, v), each (..., V, N) (pixels), of X (..., N, 3)
    world points (the rig's unit), without stacking them: the same numbers, for hot paths
    that use the coordinates apart. Numpy's warnings for points in a focal plane are not
    silenced here (project_views silences them)."""
    return project_uvz(cameras, X)[:2]


def project_uvz(cameras, X):
    """project_uv's (u, v) and the camera-frame depths z (..., V, N) (the rig's unit; > 0 in
    front of the camera, geometry.triangulation.depths' numbers) of the same projection, for
    hot paths that need both (the cheirality test beside the reprojection error)."""
    p = cameras if isinstance(cameras, dict) else stack_cameras(cameras)
    X = np.asarray(X, dtype=np.float64)
    if not p['d12'].any():  # pinhole rig: x ~ P X (K's last row is [0, 0, 1]: h[2] = z)
        P = p['P'] if 'P' in p else p['K'] @ np.concatenate([p['R'], p['t'][..., None]], -1)
        h = _apply_views(P, X)  # (..., V, N, 3)
        z = h[..., 2]
        return h[..., 0] / z, h[..., 1] / z, z
    Rt = p['Rt'] if 'Rt' in p else np.concatenate([p['R'], p['t'][..., None]], -1)
    Xc = _apply_views(Rt, X)
    z = Xc[..., 2]
    x = Xc[..., 0] / z
    y = Xc[..., 1] / z
    # 12 coefficient arrays (V, 1), over (..., V, N)
    xd, yd = _distort(p['model'] if 'model' in p else _model_terms(p['d12']), x, y)
    K = p['K'][:, None]  # (V, 1, 3, 3)
    return (K[..., 0, 0] * xd + K[..., 0, 1] * yd + K[..., 0, 2],
            K[..., 1, 1] * yd + K[..., 1, 2], z)


def undistort_views(cameras, uv):
    """Observed pixels of every camera of a rig at once -> ideal pinhole pixels (same K).

    uv: (V, N, 2) pixels (view v seen by camera v); `cameras` is a list of Camera or the
    dict of stack_cameras. The same model and answer as Camera.undistort_points, in one
    batched Newton solve over all views (no Python loop over views or points). NaN rows
    stay NaN; points where the inversion fails become NaN.
    """
    p = cameras if isinstance(cameras, dict) else stack_cameras(cameras)
    uv = np.asarray(uv, dtype=np.float64)
    if uv.ndim != 3 or uv.shape[0] != len(p['K']) or uv.shape[2] != 2:
        raise ValueError(f'uv must have shape (V={len(p["K"])}, N, 2), got {uv.shape}')
    if not p['d12'].any():
        return uv.copy()
    model = p.get('model') or _model_terms(p['d12'])
    _, rational, prism, tangential = model
    if not (rational or prism or tangential):
        return _radial_undistort(uv, p['K'], p['d12'][:, [0, 1, 4]], 20, 1e-15)
    K = p['K'][:, None]  # (V, 1, 3, 3)
    y0 = (uv[..., 1] - K[..., 1, 2]) / K[..., 1, 1]
    x0 = (uv[..., 0] - K[..., 0, 2] - K[..., 0, 1] * y0) / K[..., 0, 0]
    x, y = _undistort_newton(p['d12'], x0, y0, 20, 1e-15, model)
    return np.stack([K[..., 0, 0] * x + K[..., 0, 1] * y + K[..., 0, 2],
                     K[..., 1, 1] * y + K[..., 1, 2]], axis=-1)
