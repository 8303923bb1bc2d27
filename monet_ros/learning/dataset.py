"""Training crops from multiview recordings, with virtual cameras kept consistent.

Every view of every instant is cropped once around the subject (a square box, enlarged
by `cache_scale` so that geometric augmentation has room) and cached in memory. A training
sample is then one warp of a cached crop: random scale, shift and in-plane rotation.
Nothing is approximated: the rotation is a rotation of the camera about its optical axis
(R' = Rz R, t' = Rz t) and the crop/scale a virtual camera (K' = S K), so

    heatmap pixel = A @ original pixel     and     heatmap pixel = K_heat d'(R' X + t')

hold together exactly for every calibration the Camera class takes (fx != fy, skew, radial,
tangential and thin-prism distortion). The image warp of a rotation by theta is
K_c Rz K_c^-1 (K_c the cached crop's intrinsics): an affine map, since Rz only mixes the
normalised x, y. OpenCV's distortion d commutes with that rotation once its non-radial
coefficients are rotated with it: the tangential offset 2 (p.x) x + |x|^2 p, p = (p2, p1),
and the prism offsets (s1, s3) r^2 + (s2, s4) r^4 are vectors that turn with x, the radial
factor does not change. So d' (ViewBatch.dist) is d with (p2, p1), (s1, s3) and (s2, s4)
rotated by theta.
"""
from dataclasses import dataclass
import warnings

import cv2
import numpy as np
import torch

from monet_ros.geometry import crop_transform
from monet_ros.models.detector import images_to_tensor


@dataclass(frozen=True)
class AugmentConfig:
    """Geometric (crop scale, shift as a fraction of the side, rotation) and photometric
    (brightness offset, contrast, per-channel gain, Gaussian noise; images in [0, 1])."""
    scale: float = 0.15
    translate: float = 0.08
    rotate_deg: float = 15.0
    brightness: float = 0.15
    contrast: float = 0.2
    color: float = 0.1
    noise: float = 0.02

    def __post_init__(self):
        for name in ('scale', 'translate', 'rotate_deg', 'brightness', 'contrast', 'color',
                     'noise'):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not np.isfinite(value) or value < 0:
                raise ValueError(f'AugmentConfig.{name} must be a finite number >= 0, '
                                 f'got {value!r}')
        if self.scale >= 1 or self.contrast >= 1:
            raise ValueError('AugmentConfig.scale and .contrast must be < 1')
        if self.rotate_deg > 90:
            raise ValueError('AugmentConfig.rotate_deg must be <= 90')


NO_AUGMENT = AugmentConfig(0, 0, 0, 0, 0, 0, 0)


def boxes_from_points(points, aspect=1.0, margin=0.25, min_side=16.0):
    """Crop boxes around 2D points, with the aspect (W/H) of the network input.

    points: (..., C, 2) image pixels, NaN = missing. Returns (..., 4) edge-coordinate boxes
    (x0, y0, x1, y1) centred on the points' bounding box, (1 + 2 margin) times its larger
    side (at least min_side); NaN where no point is finite."""
    p = np.asarray(points, dtype=np.float64)
    ok = np.isfinite(p[..., 0])
    any_ok = ok.any(axis=-1)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', RuntimeWarning)
        lo = np.nanmin(np.where(ok[..., None], p, np.nan), axis=-2)
        hi = np.nanmax(np.where(ok[..., None], p, np.nan), axis=-2)
    centre = (lo + hi) / 2.0 + 0.5                                   # pixel edges
    extent = np.maximum((hi - lo)[..., 0] / aspect, (hi - lo)[..., 1])
    height = np.maximum(extent * (1.0 + 2.0 * margin), min_side)
    width = height * aspect
    boxes = np.stack([centre[..., 0] - width / 2, centre[..., 1] - height / 2,
                      centre[..., 0] + width / 2, centre[..., 1] + height / 2], axis=-1)
    boxes[~any_ok] = np.nan
    return boxes


def fill_boxes(boxes, cameras):
    """(T, V, 4) with NaN rows -> every box filled from the nearest instant in time that has
    one for that view, or the full frame when the view has none."""
    out = np.array(boxes, dtype=np.float64)
    T = out.shape[0]
    for v, cam in enumerate(cameras):
        have = np.flatnonzero(np.isfinite(out[:, v, 0]))
        if have.size == 0:
            side = max(cam.width, cam.height)
            cx, cy = cam.width / 2, cam.height / 2
            out[:, v] = (cx - side / 2, cy - side / 2, cx + side / 2, cy + side / 2)
            continue
        nearest = have[np.abs(np.arange(T)[:, None] - have[None]).argmin(axis=1)]
        out[:, v] = out[nearest, v]
    return out


def rotate_distortion(dist, theta):
    """OpenCV distortion coefficients of a camera rotated by theta about its optical axis.

    dist (D,) with D in (0, 4, 5, 8, 12) (k1 k2 p1 p2 k3 k4 k5 k6 s1 s2 s3 s4); theta (N,)
    radians (x' = Rz(theta) x in normalised coordinates). Returns (N, 12): radial terms
    unchanged, the vectors (p2, p1), (s1, s3), (s2, s4) rotated by theta, so that
    d'(Rz x) = Rz d(x) for every normalised point x."""
    theta = np.asarray(theta, dtype=np.float64).ravel()
    d = np.zeros(12)
    d[:len(dist)] = np.asarray(dist, dtype=np.float64).ravel()
    out = np.repeat(d[None], len(theta), axis=0)
    c, s = np.cos(theta), np.sin(theta)
    for a, b in ((3, 2), (8, 10), (9, 11)):            # (x, y) components of each vector
        out[:, a] = c * d[a] - s * d[b]
        out[:, b] = s * d[a] + c * d[b]
    return out


def _rz(theta):
    """(N,) angles -> (N, 3, 3) rotations about the camera z axis."""
    c, s = np.cos(theta), np.sin(theta)
    out = np.zeros((len(theta), 3, 3))
    out[:, 0, 0], out[:, 0, 1], out[:, 1, 0], out[:, 1, 1] = c, -s, s, c
    out[:, 2, 2] = 1.0
    return out


@dataclass
class ViewBatch:
    """N augmented view crops.

    images (N, 3, H, W) float32 in [0, 1]; A (N, 3, 3) original pixels -> heatmap pixels;
    K (N, 3, 3) heatmap camera intrinsics; R (N, 3, 3), t (N, 3) its world -> camera pose;
    instants (N,), views (N,) indices; dist (N, 12) its OpenCV distortion coefficients
    (the view's, with the non-radial terms turned by the sample's rotation): heatmap pixel =
    cv2.projectPoints(X, R, t, K, dist) exactly."""
    images: torch.Tensor
    A: np.ndarray
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    instants: np.ndarray
    views: np.ndarray
    dist: np.ndarray = None

    def to_heatmap(self, points, index=slice(None)):
        """(N, C, 2) original pixels -> heatmap pixels (NaN kept) of the samples
        self[index] (a slice or index array selecting N samples)."""
        p = np.asarray(points, dtype=np.float64)
        A = self.A[index]
        return np.einsum('nij,ncj->nci', A[:, :2, :2], p) + A[:, None, :2, 2]


class CropCache:
    """Cached square-ish crops of every (instant, view) around the subject.

    recording: a learning.recording.Recording; boxes (R, V, 4) edge-coordinate boxes of the
    nominal crop (aspect of the network input); input_size (H, W); heatmap_size (h, w);
    instants (R,): the recording instant of each row of crops, default the T instants in
    order (R = T). More rows than instants crop one instant around several subjects: row
    T + j is instant instants[T + j] cropped around another subject (TrainingData). The
    `instants` of views() and of a ViewBatch are these rows.
    """

    def __init__(self, recording, boxes, input_size, heatmap_size, cache_scale=1.3,
                 instants=None):
        self.recording = recording
        self.input_size = tuple(int(x) for x in input_size)
        self.heatmap_size = tuple(int(x) for x in heatmap_size)
        if cache_scale < 1:
            raise ValueError(f'cache_scale must be >= 1, got {cache_scale}')
        T, V = recording.num_instants, recording.num_views
        rows = np.arange(T) if instants is None else np.asarray(instants, np.int64).ravel()
        if rows.size and not (rows.min() >= 0 and rows.max() < T):
            raise ValueError(f'instants must index the {T} instants of the recording')
        self.row_instants = rows
        T = len(rows)
        boxes = np.asarray(boxes, dtype=np.float64)
        if boxes.shape != (T, V, 4) or not np.all(np.isfinite(boxes)):
            raise ValueError(f'boxes must be finite (R={T}, V={V}, 4), got {boxes.shape}')
        H, W = self.input_size
        self.cache_size = (int(round(W * cache_scale)), int(round(H * cache_scale)))  # (W, H)
        self.cache_scale = float(cache_scale)
        centre = (boxes[..., :2] + boxes[..., 2:]) / 2
        half = (boxes[..., 2:] - boxes[..., :2]) / 2 * cache_scale
        self.cache_boxes = np.concatenate([centre - half, centre + half], axis=-1)
        self.S_cache = np.empty((T, V, 3, 3))
        self.crops = np.empty((T, V, self.cache_size[1], self.cache_size[0], 3), np.uint8)
        for t in range(T):                                   # one warp per image, decoded once
            for v in range(V):
                S = crop_transform(self.cache_boxes[t, v], self.cache_size)
                self.S_cache[t, v] = S
                self.crops[t, v] = cv2.warpAffine(
                    recording.frames[v][rows[t]], S[:2], self.cache_size, flags=cv2.INTER_AREA
                    if S[0, 0] < 1 else cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        Ks = np.stack([c.K for c in recording.cameras])
        self.K_cache = self.S_cache @ Ks[None]
        self.R = np.stack([c.R for c in recording.cameras])
        self.t = np.stack([c.t for c in recording.cameras])
        self.S_heat = crop_transform((0, 0, W, H), (self.heatmap_size[1], self.heatmap_size[0]))

    def views(self, instants, views, rng=None, augment=NO_AUGMENT):
        """ViewBatch of the given (instant, view) pairs, augmented with `rng`.

        instants, views: (N,) int arrays; rng: numpy Generator (None = no augmentation)."""
        instants = np.asarray(instants, dtype=np.int64).ravel()
        views = np.asarray(views, dtype=np.int64).ravel()
        N = len(instants)
        H, W = self.input_size
        Wc, Hc = self.cache_size
        if rng is None:
            augment = NO_AUGMENT
            rng = np.random.default_rng(0)
        u = rng.uniform(-1.0, 1.0, size=(N, 4))
        scale = 1.0 + augment.scale * u[:, 0]
        shift = augment.translate * u[:, 1:3]
        theta = np.deg2rad(augment.rotate_deg) * u[:, 3]
        Kc = self.K_cache[instants, views]                                 # (N, 3, 3)
        Rz = _rz(theta)
        rot_px = Kc @ Rz @ np.linalg.inv(Kc)                               # cache px -> rotated
        centre = np.stack([np.full(N, Wc / 2.0 - 0.5), np.full(N, Hc / 2.0 - 0.5),
                           np.ones(N)], axis=-1)
        centre = np.einsum('nij,nj->ni', rot_px, centre)[:, :2] + 0.5     # to pixel edges
        side = np.array([Wc, Hc], dtype=np.float64)[None] / self.cache_scale * scale[:, None]
        centre = centre + shift * side
        boxes = np.concatenate([centre - side / 2, centre + side / 2], axis=-1)
        images = np.empty((N, H, W, 3), np.uint8)
        M_in = np.empty((N, 3, 3))
        S_crop = np.empty((N, 3, 3))
        for n in range(N):                                  # one warp per sample image
            S_crop[n] = crop_transform(boxes[n], (W, H))
            M_in[n] = S_crop[n] @ rot_px[n]
            images[n] = cv2.warpAffine(self.crops[instants[n], views[n]], M_in[n, :2], (W, H),
                                       flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        A = self.S_heat[None] @ M_in @ self.S_cache[instants, views]
        K = self.S_heat[None] @ S_crop @ Kc
        R = Rz @ self.R[views]
        t = np.einsum('nij,nj->ni', Rz, self.t[views])
        dist = np.empty((N, 12))
        for v in np.unique(views):
            pick = views == v
            dist[pick] = rotate_distortion(self.recording.cameras[v].dist, theta[pick])
        tensor = images_to_tensor(images)              # the detector's own conversion
        tensor = photometric(tensor, augment, rng)
        return ViewBatch(tensor, A, K, R, t, instants, views, dist)


def photometric(images, augment, rng):
    """Batched photometric jitter of (N, 3, H, W) images in [0, 1] (clamped)."""
    if not (augment.brightness or augment.contrast or augment.color or augment.noise):
        return images
    N = images.shape[0]
    g = torch.Generator().manual_seed(int(rng.integers(2**31)))
    r = torch.from_numpy(rng.uniform(-1, 1, size=(N, 5))).float()
    mean = images.mean(dim=(1, 2, 3), keepdim=True)
    out = (images - mean) * (1 + augment.contrast * r[:, 0, None, None, None]) + mean
    out = out * (1 + augment.color * r[:, 1:4, None, None]) + \
        augment.brightness * r[:, 4, None, None, None]
    if augment.noise:
        out = out + augment.noise * torch.randn(out.shape, generator=g)
    return out.clamp_(0.0, 1.0)
