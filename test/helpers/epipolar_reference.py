"""Brute-force epipolar divergence (no rectification) and heatmap rigs for its tests and bench.

The reference follows the paper's definition directly (Eq. 4-8): an epipolar plane is the
half-plane through the baseline C_i C_j at angle theta around it; Q(theta) is the maximum of
the heatmap along that plane's epipolar line, sampled in the original heatmap.
"""
import math

import numpy as np
from scipy.ndimage import map_coordinates
import torch
import torch.nn.functional as F

from helpers.rigs import look_at, random_camera
from monet_ros.geometry import Camera


def crop_to_subject(camera, size=(46, 46), half_extent=0.9, centre=(0.0, 0.0, 0.0)):
    """Heatmap virtual camera (Camera.crop) of a square box around a subject of
    +-half_extent metres at `centre`; size (h, w)."""
    uv = camera.project(np.asarray(centre, float)[None])[0]
    depth = (camera.R @ np.asarray(centre, float) + camera.t)[2]
    half = camera.K[0, 0] * half_extent / depth
    box = (uv[0] - half, uv[1] - half, uv[0] + half, uv[1] + half)
    return camera.crop(box, (size[1], size[0]))


def random_heatmap_pair(rng, size=(46, 46), min_angle_deg=45.0):
    """Two random heatmap cameras looking at the origin whose baseline is at least
    min_angle_deg from the rays to the origin (>= ~20 degrees from every window ray)."""
    while True:
        cams = [crop_to_subject(random_camera(rng, name=f'cam{k}', distortion=False), size)
                for k in range(2)]
        base = cams[1].center - cams[0].center
        ok = True
        for cam in cams:
            ray = -cam.center / np.linalg.norm(cam.center)
            cos = abs(ray @ base) / np.linalg.norm(base)
            ok &= cos < math.cos(math.radians(min_angle_deg))
        if ok:
            return cams


def ring_rig(num_views=8, size=(46, 46), radius=3.0, height=1.5, focal=1000.0):
    """num_views heatmap cameras evenly on a horizontal ring, looking at the origin."""
    cams = []
    for k in range(num_views):
        a = 2 * math.pi * k / num_views
        center = np.array([radius * math.cos(a), radius * math.sin(a), height])
        R = look_at(center, (0.0, 0.0, 0.0))
        K = np.array([[focal, 0.0, 640.0], [0.0, focal, 480.0], [0.0, 0.0, 1.0]])
        cam = Camera(f'cam{k}', K, np.zeros(5), R, -R @ center, 1280, 960)
        cams.append(crop_to_subject(cam, size))
    return cams


def stack(cams, dtype=torch.float64):
    """K (V, 3, 3), R (V, 3, 3), t (V, 3) tensors of a list of Cameras."""
    return tuple(torch.tensor(np.stack([getattr(c, a) for c in cams]), dtype=dtype)
                 for a in ('K', 'R', 't'))


def plane_frame(cam_i, cam_j, ref):
    """Unit baseline e1 and two unit vectors u0, v0 orthogonal to it (u0 from `ref`)."""
    e1 = cam_j.center - cam_i.center
    e1 /= np.linalg.norm(e1)
    u0 = np.asarray(ref, float) - (np.asarray(ref, float) @ e1) * e1
    u0 /= np.linalg.norm(u0)
    return e1, u0, np.cross(e1, u0)


def plane_angle(X, cam_i, e1, u0, v0):
    """Epipolar-plane angle theta of world point X: atan2 of its offset from the baseline."""
    d = np.asarray(X, float) - cam_i.center
    return math.atan2(d @ v0, d @ u0)


def plane_row_max_numpy(heat, cam, e1, u0, v0, thetas, step=0.05):
    """Q (C, P) unnormalised: max of heat (C, h, w) along the epipolar line of each half-plane
    w(theta) = cos(theta) u0 + sin(theta) v0 around the baseline e1, sampled every `step`
    pixels by bilinear interpolation (scipy), only on that half-plane's side of the epipole."""
    C, h, w = heat.shape
    out = np.zeros((C, len(thetas)))
    back = cam.R.T @ np.linalg.inv(cam.K)
    lo, hi = np.array([-0.5, -0.5]), np.array([w - 0.5, h - 0.5])
    for k, theta in enumerate(thetas):
        wdir = math.cos(theta) * u0 + math.sin(theta) * v0
        line = np.linalg.inv(cam.K).T @ cam.R @ np.cross(e1, wdir)
        normal = line[:2] / np.linalg.norm(line[:2])
        c = line[2] / np.linalg.norm(line[:2])
        centre = (lo + hi) / 2
        p0 = centre - (normal @ centre + c) * normal
        direction = np.array([-normal[1], normal[0]])
        t = np.arange(-np.linalg.norm(hi - lo), np.linalg.norm(hi - lo), step)
        pts = p0 + t[:, None] * direction
        inside = np.all((pts >= lo) & (pts <= hi), axis=1)
        rays = np.c_[pts, np.ones(len(pts))] @ back.T
        pts = pts[inside & (rays @ wdir > 0)]
        if len(pts) == 0:
            continue
        for ch in range(C):
            vals = map_coordinates(heat[ch], [pts[:, 1], pts[:, 0]], order=1,
                                   mode='grid-constant', cval=0.0)
            out[ch, k] = max(vals.max(), 0.0)
    return out


def kl_rows(q_i, q_j, eps=1e-6):
    """KL over the last axis of two unnormalised row profiles (numpy)."""
    p = q_i / max(q_i.sum(-1, keepdims=True).min(), 1e-12)
    q = q_j / max(q_j.sum(-1, keepdims=True).min(), 1e-12)
    return np.maximum((p * (np.log(p + eps) - np.log(q + eps))).sum(-1), 0.0)


def line_row_max_torch(heat, K, R, normals, spacing=1.0):
    """Batched brute force: (N, C, P) max of heat (N, C, h, w) along the epipolar lines of the
    world plane normals (N, P, 3) (through the camera centre), bilinear samples every
    `spacing` pixels (at most) along each line clipped to the heatmap window.

    Lines are full lines: valid pairs' windows see one half-plane only (|theta| < 90 degrees).
    """
    N, C, h, w = heat.shape
    lines = normals.to(K.dtype) @ (R.transpose(-1, -2) @ torch.linalg.inv(K))  # K^-T R n
    ab = lines[..., :2]
    norm = ab.norm(dim=-1, keepdim=True)
    ab, c = ab / norm, lines[..., 2:] / norm
    lo = torch.tensor([-0.5, -0.5], dtype=K.dtype)
    hi = torch.tensor([w - 0.5, h - 0.5], dtype=K.dtype)
    centre = (lo + hi) / 2
    p0 = centre - ((ab * centre).sum(-1, keepdim=True) + c) * ab
    direction = torch.stack([-ab[..., 1], ab[..., 0]], -1)
    # Slab clipping of p0 + s direction to the window.
    safe = torch.where(direction.abs() > 1e-12, direction, torch.full_like(direction, 1e-12))
    s1, s2 = (lo - p0) / safe, (hi - p0) / safe
    s_lo = torch.minimum(s1, s2).amax(-1)
    s_hi = torch.maximum(s1, s2).amin(-1)
    hit = s_hi > s_lo
    samples = math.ceil(math.hypot(h, w) / spacing) + 1
    frac = torch.linspace(0.0, 1.0, samples, dtype=K.dtype)
    s = s_lo[..., None] + (s_hi - s_lo)[..., None] * frac               # (N, P, S)
    pts = p0[..., None, :] + s[..., None] * direction[..., None, :]      # (N, P, S, 2)
    grid = (pts + 0.5) * torch.stack([2.0 / hi.new_tensor(w), 2.0 / hi.new_tensor(h)]) - 1.0
    grid = torch.where(hit[..., None, None], grid, torch.full_like(grid, -3.0))
    sampled = F.grid_sample(heat, grid.to(heat.dtype), mode='bilinear', padding_mode='zeros',
                            align_corners=False)
    return sampled.amax(-1).clamp_min(0.0)


def rect_row_normals(R_rect, theta):
    """World normals (N, P, 3) of the epipolar planes of rectified rows theta (N, P): the
    half-plane direction is sin(theta) y + cos(theta) z of the rectified frame."""
    y, z = R_rect[:, 1], R_rect[:, 2]
    wdir = torch.sin(theta)[..., None] * y[:, None] + torch.cos(theta)[..., None] * z[:, None]
    return torch.linalg.cross(R_rect[:, None, 0].expand_as(wdir), wdir, dim=-1)
