"""Render the synthetic subject into each camera of a rig (numpy + cv2, no ROS).

- Background: a room seen through each camera's lens (ray cast per pixel once per camera,
  distortion included): a tiled, noisy floor (z = 0) and a cylindrical wall covered with
  seeded clutter (shapes, lines, noise), so all views see one consistent 3D scene.
- Subject: every limb is a capsule (see subject.Capsule). Its outline is sampled in 3D
  (circles around points along the axis, perpendicular to the viewing ray), projected with
  Camera.project (so lens distortion bends it) and filled as a convex polygon; nested,
  shrinking polygons shifted towards the light give the shading. Limbs are painted far to
  near (painter's algorithm on the distance of the nearest surface point of the axis), so a
  nearer limb overwrites a farther one. Left and right limbs share the same material.
- Photometry: a soft blob shadow, per-camera white balance and exposure, slow global
  light flicker, and sensor noise (a seeded bank of noise images).

Occlusion of keypoints (for ground truth / labels) is geometric: `occlusion` tests the
ray from the camera centre to the keypoint against every limb capsule not attached to it.
"""
from dataclasses import dataclass

import cv2
import numpy as np

from monet_ros.geometry import project_views

SHIFT = 4                  # sub-pixel bits of cv2 polygon vertices
_SCALE = 1 << SHIFT

# Base materials (RGB 0..255) before seeded variation; left/right limbs share a part.
PALETTES = {
    'torso': [(40, 90, 160), (150, 40, 40), (60, 120, 60), (200, 170, 60), (90, 60, 130)],
    'arm': None,            # sleeves: the torso colour, a little darker
    'hips': [(50, 50, 70), (90, 70, 50), (40, 60, 90), (110, 110, 110)],
    'leg': None,            # trousers: the hips colour
    'skin': [(225, 180, 150), (190, 140, 105), (140, 95, 70), (240, 200, 175)],
    'head': None,           # the skin colour
    'shoe': [(30, 30, 30), (200, 200, 200), (120, 60, 30)],
    'tail': None,
    'paw': [(60, 45, 35), (230, 225, 215), (30, 30, 30)],
}


@dataclass(frozen=True)
class RenderConfig:
    """noise: sensor noise std (DN); flicker: relative amplitude of the global light
    flicker; levels: shading rings per limb (1 = flat); samples: outline points per axis
    point; axis_points: axis points per capsule (>= 2; more follow distortion better);
    clutter: shapes on the wall texture; shadow: draw a blob shadow under the subject."""

    noise: float = 3.0
    flicker: float = 0.04
    levels: int = 4
    samples: int = 12
    axis_points: int = 3
    clutter: int = 150
    shadow: bool = True

    def __post_init__(self):
        checks = (('noise', 0 <= self.noise <= 50), ('flicker', 0 <= self.flicker <= 0.5),
                  ('levels', isinstance(self.levels, int) and 1 <= self.levels <= 8),
                  ('samples', isinstance(self.samples, int) and 6 <= self.samples <= 64),
                  ('axis_points', isinstance(self.axis_points, int)
                   and 2 <= self.axis_points <= 16),
                  ('clutter', isinstance(self.clutter, int) and 0 <= self.clutter <= 10000))
        for name, ok in checks:
            if not ok:
                raise ValueError(f'render config: field {name!r} out of range: '
                                 f'{getattr(self, name)!r}')


# Colour mixed into the parts of the subject's left side (`left_<part>`, --distinct-sides).
LEFT_TINT = np.array([240.0, 200.0, 20.0])
SIDED = 'left_'


def sided_parts(capsules):
    """Part names with the subject's left limbs renamed `left_<part>` (own material)."""
    return tuple(SIDED + c.part if c.a.startswith(('l_', 'lf_', 'lh_')) else c.part
                 for c in capsules)


def part_colors(parts, rng):
    """dict part -> (3,) float RGB for the parts present; linked parts share a colour;
    `left_<part>` is <part>'s colour mixed 60% with LEFT_TINT (left and right limbs told
    apart)."""
    base = {name: np.array(pal[rng.integers(len(pal))], float)
            for name, pal in PALETTES.items() if pal is not None}
    base['arm'] = base['torso'] * 0.85
    base['leg'] = base['hips']
    base['head'] = base['skin']
    base['tail'] = base['torso']
    # an option (no draw from rng: a seed's colours stay): neutral grey pillars
    base['occluder'] = np.array([128.0, 124.0, 118.0])
    if 'paw' in parts or 'tail' in parts:          # an animal: one fur colour everywhere
        fur = np.array(PALETTES['torso'][rng.integers(5)], float) * 0.8 + 40
        for name in ('torso', 'head', 'leg', 'tail'):
            base[name] = fur
    for part in parts:
        if part.startswith(SIDED):
            base[part] = 0.4 * base[part[len(SIDED):]] + 0.6 * LEFT_TINT
    return {p: np.clip(base[p], 0, 255) for p in set(parts)}


# ---------------------------------------------------------------------------- geometry

def _orthonormal(w):
    """Two unit vectors (..., 3) perpendicular to unit vectors w (..., 3) and to each other."""
    helper = np.where(np.abs(w[..., 2:3]) < 0.9, [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    e1 = np.cross(w, helper)
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    return e1, np.cross(w, e1)


def capsule_outlines(camera, A, B, radii, light, levels=4, samples=12, axis_points=3):
    """Projected outlines of capsules for one camera.

    A, B: (T, P, 3) axis end points; radii (P,); light (3,) unit direction towards the light.
    Returns (outlines (T, P, L, S, 2) pixels with S = axis_points * samples, depth (T, P)
    distance from the camera centre to the nearest surface point of the axis,
    facing (T, P) in [0, 1]: how much the visible side faces the light).
    Level l has radius r (1 - l / L), shifted towards the light by 0.6 (r - r_l).
    """
    A = np.asarray(A, float)
    B = np.asarray(B, float)
    c = camera.center
    s = np.linspace(0.0, 1.0, axis_points)
    axis = A[:, :, None] + (B - A)[:, :, None] * s[:, None]        # (T, P, M, 3)
    view = axis - c
    dist = np.linalg.norm(view, axis=-1, keepdims=True)
    w = view / dist                                                # (T, P, M, 3)
    e1, e2 = _orthonormal(w)
    theta = np.linspace(0, 2 * np.pi, samples, endpoint=False)
    ring = (np.cos(theta)[:, None] * e1[..., None, :]
            + np.sin(theta)[:, None] * e2[..., None, :])           # (T, P, M, S, 3)
    # light direction perpendicular to the viewing ray of the capsule's middle
    w_mid = w[:, :, axis_points // 2]
    lp = light - (w_mid @ light)[..., None] * w_mid
    norm = np.linalg.norm(lp, axis=-1, keepdims=True)
    lp = np.where(norm > 1e-9, lp / np.maximum(norm, 1e-9), 0.0)   # (T, P, 3)
    scale = 1.0 - np.arange(levels) / levels                       # (L,)
    r_l = radii[None, :, None] * scale[None, None, :]              # (1, P, L)
    offset = 0.6 * (radii[None, :, None] - r_l)[..., None] * lp[:, :, None]   # (T, P, L, 3)
    points = (axis[:, :, None, :, None] + offset[:, :, :, None, None]
              + r_l[..., None, None, None] * ring[:, :, None])     # (T, P, L, M, S, 3)
    T, P = A.shape[:2]
    uv = camera.project(points.reshape(-1, 3)).reshape(T, P, levels, axis_points, samples, 2)
    # a capsule whose axis comes closer to the image plane than its radius is not drawn
    axis_depth = view @ camera.R[2]                                 # (T, P, M)
    behind = np.any(axis_depth <= radii[None, :, None] + 1e-3, axis=-1)
    uv[behind] = np.nan
    uv = uv.reshape(T, P, levels, axis_points * samples, 2)
    depth = dist[..., 0].min(axis=-1) - radii[None]
    facing = 0.5 * (1 - (w_mid @ light))
    return uv, depth, facing


def draw_capsules(image, outlines, depth, colors, facing=None, ambient=0.45):
    """Paint one frame's capsules into image (H, W, 3) uint8, far to near.

    outlines (P, L, S, 2) pixels; depth (P,); colors (P, 3) RGB; facing (P,) in [0, 1] or
    None. Level 0 (the rim) is darkest, the innermost level brightest. Returns the drawing
    order (P,) (far to near).
    """
    P, L = outlines.shape[:2]
    facing = np.full(P, 0.5) if facing is None else facing
    order = np.argsort(-depth, kind='stable')
    brightness = ambient + (1 - ambient) * (np.arange(L) + 1) / L        # (L,)
    fixed = np.round(outlines * _SCALE)
    finite = np.isfinite(fixed).all(axis=(-1, -2))                      # (P, L)
    fixed = np.where(np.isfinite(fixed), fixed, 0).astype(np.int32)
    for p in order:
        gain = brightness * (0.75 + 0.5 * facing[p]) if L > 1 else np.ones(1)
        shades = np.clip(colors[p][None] * gain[:, None], 0, 255)
        for level in range(L):
            if not finite[p, level]:
                continue
            hull = cv2.convexHull(fixed[p, level])
            cv2.fillConvexPoly(image, hull, shades[level].tolist(), cv2.LINE_AA, SHIFT)
    return order


# ---------------------------------------------------------------------------- occlusion

def segment_distance(p0, p1, q0, q1, eps=1e-12):
    """Distance between segments [p0, p1] and [q0, q1] (broadcast (..., 3) arrays) and the
    parameter s in [0, 1] of the closest point on the first segment (Ericson, RTCD 5.1.9)."""
    d1 = p1 - p0
    d2 = q1 - q0
    r = p0 - q0
    a = (d1 * d1).sum(-1)
    e = (d2 * d2).sum(-1)
    f = (d2 * r).sum(-1)
    c = (d1 * r).sum(-1)
    b = (d1 * d2).sum(-1)
    denom = a * e - b * b
    safe_a = np.maximum(a, eps)
    safe_e = np.maximum(e, eps)
    s = np.where(denom > eps, np.clip((b * f - c * e) / np.maximum(denom, eps), 0, 1), 0.0)
    s = np.where(e > eps, s, np.clip(-c / safe_a, 0, 1))
    t = np.where(e > eps, (b * s + f) / safe_e, 0.0)
    s = np.where(t < 0, np.clip(-c / safe_a, 0, 1), np.where(t > 1, np.clip((b - c) / safe_a,
                                                                          0, 1), s))
    t = np.clip(t, 0, 1)
    closest_p = p0 + d1 * s[..., None]
    closest_q = q0 + d2 * t[..., None]
    return np.linalg.norm(closest_p - closest_q, axis=-1), s


def occlusion(cameras, X, A, B, radii, attached):
    """(T, V, C) bool: keypoint c is hidden in view v at time t by a limb not attached to it.

    X (T, C, 3) keypoints; A, B (T, P, 3) capsule axes; radii (P,); attached (P, C) bool.
    """
    centers = np.stack([cam.center for cam in cameras])                 # (V, 3)
    p0 = centers[None, :, None, None, :]                                 # (1, V, 1, 1, 3)
    p1 = X[:, None, :, None, :]                                          # (T, 1, C, 1, 3)
    q0 = A[:, None, None]                                                # (T, 1, 1, P, 3)
    q1 = B[:, None, None]
    dist, _ = segment_distance(p0, p1, q0, q1)                           # (T, V, C, P)
    blocked = (dist < radii) & ~attached.T[None, None]
    return blocked.any(axis=-1)


def in_image(cameras, X):
    """(points2d (T, V, C, 2), inside (T, V, C) bool): projections of X (T, C, 3) and
    whether each lies in front of the camera and inside the image (pixel-edge box)."""
    uv = project_views(cameras, X)
    depth = np.einsum('vij,tcj->tvci', np.stack([c.R for c in cameras]), X)[..., 2] \
        + np.stack([c.t for c in cameras])[None, :, None, 2]
    size = np.array([[c.width, c.height] for c in cameras], float)[None, :, None]
    inside = ((depth > 0) & np.all(np.isfinite(uv), -1) & np.all(uv >= -0.5, -1)
              & np.all(uv < size - 0.5, -1))
    return uv, inside


# ---------------------------------------------------------------------------- background

def _noise_texture(rng, height, width, octaves=((8, 0.5), (32, 0.3), (128, 0.2))):
    """(H, W) float32 smooth value noise in about [-1, 1]."""
    out = np.zeros((height, width), np.float32)
    for cells, weight in octaves:
        grid = rng.uniform(-1, 1, (max(2, cells * height // width), cells)).astype(np.float32)
        out += weight * cv2.resize(grid, (width, height), interpolation=cv2.INTER_CUBIC)
    return out


def _clutter(rng, image, count):
    """Draw `count` seeded shapes (rectangles, circles, lines, polygons) onto image."""
    h, w = image.shape[:2]
    for _ in range(count):
        color = rng.integers(0, 256, 3).tolist()
        kind = rng.integers(5)
        x, y = int(rng.integers(w)), int(rng.integers(h))
        size = int(rng.integers(h // 30 + 2, h // 4 + 3))
        if kind == 0:
            cv2.rectangle(image, (x, y), (x + int(size * rng.uniform(0.3, 2)), y + size),
                          color, -1)
        elif kind == 1:
            cv2.circle(image, (x, y), size // 2, color, -1, cv2.LINE_AA)
        elif kind == 2:
            end = (x + int(rng.integers(-size, size)), y + int(rng.integers(-size, size)))
            cv2.line(image, (x, y), end, color, int(rng.integers(1, 6)), cv2.LINE_AA)
        elif kind == 3:
            pts = (np.array([x, y]) + rng.integers(-size, size, (int(rng.integers(3, 7)), 2)))
            cv2.fillPoly(image, [cv2.convexHull(pts.astype(np.int32))], color, cv2.LINE_AA)
        else:
            cv2.ellipse(image, (x, y), (size // 2, max(1, size // 6)),
                        float(rng.uniform(0, 180)), 0, 360, color, -1, cv2.LINE_AA)


class Scene:
    """The static room and the materials/lighting of one seeded recording.

    cameras: the rig (sizes the room); parts: the subject's capsule parts.
    background(camera) -> (H, W, 3) uint8; render(camera index, frame index, ...) draws.
    """

    FLOOR_TEX = 1024
    RAY_STEP = 4
    WALL_TEX = (512, 4096)     # (height, width)

    def __init__(self, cameras, parts, seed=0, config=None):
        self.config = config or RenderConfig()
        rng = np.random.default_rng([int(seed), 0x5245])       # 'RE': render stream
        reach = max(np.hypot(*cam.center[:2]) for cam in cameras)
        self.wall_radius = max(6.0, 1.6 * reach + 1.0)
        self.wall_height = max(3.5, 1.5 * max(cam.center[2] for cam in cameras))
        self.floor_half = self.wall_radius * 1.05
        elevation = rng.uniform(np.radians(40), np.radians(70))
        azimuth = rng.uniform(0, 2 * np.pi)
        self.light = np.array([np.cos(elevation) * np.cos(azimuth),
                               np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])
        self.floor = self._floor_texture(rng)
        self.wall = self._wall_texture(rng)
        self.ceiling = rng.integers(170, 235, 3).astype(np.uint8)
        self.colors = part_colors(parts, rng)
        self.part_rgb = np.array([self.colors[p] for p in parts])
        n = len(cameras)
        self.white_balance = rng.uniform(0.9, 1.1, (n, 3))
        self.exposure = rng.uniform(0.85, 1.1, n)
        self.flicker_phase = rng.uniform(0, 2 * np.pi, 2)
        self._noise_rng = np.random.default_rng(rng.integers(1 << 62))
        self._noise_banks = {}

    def _floor_texture(self, rng):
        n = self.FLOOR_TEX
        tiles = int(round(2 * self.floor_half / 0.5))               # 0.5 m tiles
        tile_shade = rng.uniform(-25, 25, (tiles, tiles)).astype(np.float32)
        shade = cv2.resize(tile_shade, (n, n), interpolation=cv2.INTER_NEAREST)
        base = rng.integers(90, 170, 3).astype(np.float32)
        tex = base + shade[..., None] + 18 * _noise_texture(rng, n, n)[..., None]
        grout = (np.arange(n) * tiles // n) != ((np.arange(n) + 2) * tiles // n)
        tex[grout] *= 0.6
        tex[:, grout] *= 0.6
        tex = np.clip(tex, 0, 255).astype(np.uint8)
        _clutter(rng, tex, self.config.clutter // 5)                # rugs, marks
        return tex

    def _wall_texture(self, rng):
        h, w = self.WALL_TEX
        base = rng.integers(120, 210, 3).astype(np.float32)
        tex = base + 30 * _noise_texture(rng, h, w)[..., None]
        tex = np.clip(tex, 0, 255).astype(np.uint8)
        _clutter(rng, tex, self.config.clutter)
        return tex

    def background(self, camera):
        """(H, W, 3) uint8 view of the room through `camera` (distortion included)."""
        W, H = camera.width, camera.height
        # viewing rays, undistorted on a grid of every STEP-th pixel and interpolated
        # (cv2.resize maps low-res pixel i to full-res coordinate STEP i + (STEP - 1) / 2)
        step = self.RAY_STEP
        w, h = -(-W // step), -(-H // step)
        u, v = np.meshgrid(np.arange(w) * step + (step - 1) / 2.0,
                           np.arange(h) * step + (step - 1) / 2.0)
        uv = np.stack([u.ravel(), v.ravel()], axis=1)
        xy = camera.pixels_to_normalized(camera.undistort_points(uv))
        coarse = (np.concatenate([xy, np.ones((len(xy), 1))], axis=1) @ camera.R)  # R^T d
        coarse = coarse.reshape(h, w, 3).astype(np.float32)
        rays = cv2.resize(coarse, (w * step, h * step), interpolation=cv2.INTER_LINEAR)
        rays = rays[:H, :W].reshape(-1, 3).astype(np.float64)
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        c = camera.center
        # wall: |c_xy + s d_xy| = radius, the positive root
        a = (rays[:, :2] ** 2).sum(1)
        b = 2 * rays[:, :2] @ c[:2]
        q = c[:2] @ c[:2] - self.wall_radius ** 2
        s_wall = (-b + np.sqrt(np.maximum(b * b - 4 * a * q, 0))) / np.maximum(2 * a, 1e-12)
        with np.errstate(divide='ignore', invalid='ignore'):
            s_floor = np.where(rays[:, 2] < -1e-9, -c[2] / rays[:, 2], np.inf)
        floor = s_floor < s_wall
        hit = c + rays * np.where(floor, s_floor, s_wall)[:, None]
        n = self.FLOOR_TEX
        fx = ((hit[:, 0] + self.floor_half) / (2 * self.floor_half) * n - 0.5)
        fy = ((hit[:, 1] + self.floor_half) / (2 * self.floor_half) * n - 0.5)
        th, tw = self.WALL_TEX
        wx = (np.arctan2(hit[:, 1], hit[:, 0]) % (2 * np.pi)) / (2 * np.pi) * tw - 0.5
        wy = (self.wall_height - hit[:, 2]) / self.wall_height * th - 0.5
        mx = np.where(floor, fx, wx).reshape(H, W).astype(np.float32)
        my = np.where(floor, fy, wy).reshape(H, W).astype(np.float32)
        floor_img = cv2.remap(self.floor, mx, my, cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_REFLECT)
        wall_img = cv2.remap(self.wall, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
        out = np.where(floor.reshape(H, W, 1), floor_img, wall_img)
        ceiling = (~floor & (hit[:, 2] > self.wall_height)).reshape(H, W)
        out[ceiling] = self.ceiling
        # lighting: floor lit by the light's elevation, wall by its facing
        normal = np.where(floor[:, None], [0.0, 0.0, 1.0],
                          -np.concatenate([hit[:, :2], np.zeros((len(hit), 1))], 1)
                          / self.wall_radius)
        lit = (0.6 + 0.4 * np.clip(normal @ self.light, 0, 1)).reshape(H, W, 1)
        return np.clip(out * lit, 0, 255).astype(np.uint8)

    def noise_bank(self, height, width, size=8):
        """(size, H, W, 3) pairs of uint8 (positive, negative) noise images."""
        key = (height, width)
        if key not in self._noise_banks:
            sigma = self.config.noise
            noise = self._noise_rng.standard_normal((size, height, width, 3), np.float32)
            noise = np.round(noise * sigma).astype(np.int16)
            self._noise_banks[key] = (np.clip(noise, 0, 255).astype(np.uint8),
                                      np.clip(-noise, 0, 255).astype(np.uint8))
        return self._noise_banks[key]

    def shadow(self, image, camera, root, radius):
        """Darken the floor under the subject: an ellipse of `radius` m around root (3,)."""
        theta = np.linspace(0, 2 * np.pi, 24, endpoint=False)
        ring = np.stack([root[0] + radius * np.cos(theta), root[1] + radius * np.sin(theta),
                         np.full_like(theta, 0.002)], 1)
        if np.any(camera.to_camera(ring)[:, 2] <= 0.05):
            return
        uv = camera.project(ring)
        sigma = max(1.0, np.ptp(uv[:, 0]) / 12)
        pad = int(np.ceil(3 * sigma)) + 2                 # the blur fades out inside the box
        x0, y0 = np.floor(uv.min(0)).astype(int) - pad
        x1, y1 = np.ceil(uv.max(0)).astype(int) + pad
        if x1 <= 0 or y1 <= 0 or x0 >= camera.width or y0 >= camera.height:
            return
        mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
        pts = np.round((uv - [x0, y0]) * _SCALE).astype(np.int32)
        cv2.fillConvexPoly(mask, pts, 90, cv2.LINE_AA, SHIFT)
        mask = cv2.GaussianBlur(mask, (0, 0), sigma, borderType=cv2.BORDER_CONSTANT)
        cx0, cy0 = max(x0, 0), max(y0, 0)
        cx1, cy1 = min(x1, camera.width), min(y1, camera.height)
        mask = mask[cy0 - y0:cy1 - y0, cx0 - x0:cx1 - x0]
        roi = image[cy0:cy1, cx0:cx1]
        roi[:] = (roi * (1 - mask[..., None] / 255.0)).astype(np.uint8)

    def render(self, view, frame, camera, background, outlines, depth, facing, root=None,
               shadow_radius=0.35):
        """One image (H, W, 3) uint8 rgb: background, shadow, limbs, photometry, noise.

        view / frame: indices (photometry and noise are seeded by them); outlines (P, L, S,
        2), depth (P,), facing (P,) from capsule_outlines at this frame; root (3,) or None.
        """
        image = background.copy()
        if self.config.shadow and root is not None:
            self.shadow(image, camera, root, shadow_radius)
        draw_capsules(image, outlines, depth, self.part_rgb, facing)
        flicker = 1 + self.config.flicker * np.sin(0.7 * frame + self.flicker_phase[0]) \
            * np.sin(0.13 * frame + self.flicker_phase[1])
        gain = self.white_balance[view] * self.exposure[view] * flicker
        image = cv2.multiply(image, (*gain.tolist(), 0.0))
        if self.config.noise > 0:
            pos, neg = self.noise_bank(camera.height, camera.width)
            k = (frame * 7919 + view * 104729) % len(pos)
            image = cv2.subtract(cv2.add(image, pos[k]), neg[k])
        return image
