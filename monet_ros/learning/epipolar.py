"""Epipolar divergence (MONET, Yao et al., ICCV 2019) and the multiview loss L_E, batched torch.

For two views i, j of one keypoint, every epipolar plane contains the baseline C_i C_j and
is named by its angle theta around the baseline. A 3D point lies on one plane, so its two
detections must agree on theta. Following the paper, both heatmaps are stereo-rectified so
that epipolar lines become rows, each row is max-pooled, Q(v) = max_u P(u, v) is normalised
over the rows and the two distributions are compared with KL(Q_i || Q_j->i).

Rectification (inverse warping, ``torch.nn.functional.grid_sample``, bilinear): the shared
rectified frame R_rect (``geometry.rectifying_rotation``) has x = the baseline direction and
z = the mean optical axis made orthogonal to it. A rectified pixel (row k, column l) is the ray

    d = R_rect^T (cos a_l, sin a_l sin theta_k, sin a_l cos theta_k)

(theta_k: epipolar-plane angle, a_l: angle of the ray from the baseline inside that plane),
sampled in the original heatmap at the pixel K R d. Row k of *both* rectified heatmaps is the
same plane theta_k, so the paper's row map v -> a v + b is the identity (a = 1, b = 0). This is
the spherical ("polar") form of stereo rectification rather than a planar homography: rows are
exactly the same epipolar lines, but columns stay evenly spaced along each line (a planar
rectification stretches the side near the epipole by 1 / sin^2(a), 33x at 10 degrees) and no
ray has to lie in front of a rectified image plane. The rectified window is the (theta, a)
range of the warped heatmap border (corners and edge samples), theta the planes that both
windows see (rows only one window sees would compare a detection with zero padding) and
a per view; rows are chosen so that at each window's centre one rectified row step is at
most ``max_spacing`` heatmap pixels, columns half that: a bilinear heatmap has cusps at pixel
centres, so a sampled row max falls short of the supremum along the line linearly in the
spacing (measured: <= 4% for Gaussians of sigma 1.5 px at 0.5 px columns).

Degenerate pairs (coincident centres; epipole inside or within ``min_angle_deg`` of a heatmap
window, i.e. the baseline nearly parallel to viewing rays; windows more than 90 degrees
around the baseline from the shared frame) are flagged: their divergence is 0 with no
gradient, never NaN. ``valid_view_pairs`` lists the non-degenerate pairs of a rig.
"""
from dataclasses import dataclass
import math

import torch
import torch.nn.functional as F

from monet_ros.geometry import rectifying_rotation

_EDGE_SAMPLES = 16          # samples per heatmap border edge used to bound the window
_OUTSIDE = -3.0             # grid_sample coordinate that reads the zero padding


def _check_camera_batch(name, K, R, t, batch):
    if K.shape[-2:] != (3, 3) or R.shape[-2:] != (3, 3) or t.shape[-1] != 3:
        raise ValueError(f'{name}: expected K (..., 3, 3), R (..., 3, 3), t (..., 3), got '
                         f'{tuple(K.shape)}, {tuple(R.shape)}, {tuple(t.shape)}')
    if K.shape[:-2] != batch or R.shape[:-2] != batch or t.shape[:-1] != batch:
        raise ValueError(f'{name}: camera batch shapes {tuple(K.shape[:-2])}, '
                         f'{tuple(R.shape[:-2])}, {tuple(t.shape[:-1])} do not match the '
                         f'heatmap batch {tuple(batch)}')


def _check_options(min_angle_deg, max_spacing, eps, rows, cols, max_grid):
    if not 0.0 < min_angle_deg < 90.0:
        raise ValueError(f'min_angle_deg must be in (0, 90), got {min_angle_deg}')
    if not max_spacing > 0.0:
        raise ValueError(f'max_spacing must be > 0 heatmap pixels, got {max_spacing}')
    if not eps > 0.0:
        raise ValueError(f'eps must be > 0, got {eps}')
    for name, value in (('rows', rows), ('cols', cols), ('max_grid', max_grid)):
        if value is not None and (int(value) != value or value < 2):
            raise ValueError(f'{name} must be an integer >= 2 or None, got {value}')


def _border_pixels(size, dtype, device):
    """(4 * _EDGE_SAMPLES, 2) points on the pixel-edge border of an (h, w) window."""
    h, w = size
    s = torch.linspace(0.0, 1.0, _EDGE_SAMPLES, dtype=dtype, device=device)
    x0, y0, x1, y1 = -0.5, -0.5, w - 0.5, h - 0.5
    xs, ys = x0 + s * (x1 - x0), y0 + s * (y1 - y0)
    return torch.cat([
        torch.stack([xs, torch.full_like(xs, y0)], -1),
        torch.stack([xs, torch.full_like(xs, y1)], -1),
        torch.stack([torch.full_like(ys, x0), ys], -1),
        torch.stack([torch.full_like(ys, x1), ys], -1)])


def _apply(M, x):
    """M (N, 3, 3) applied to vectors x (N, ..., 3). Elementwise, not bmm: batched 3x3
    matmuls start a thread team per call, which dominates on a loaded CPU."""
    M = M.reshape(M.shape[0], *([1] * (x.dim() - 2)), 3, 3)
    return (M * x[..., None, :]).sum(-1)


def _mm(A, B):
    """(N, 3, 3) @ (N, 3, 3), elementwise."""
    return (A[..., :, :, None] * B[..., None, :, :]).sum(-2)


def _rays(K_inv_Rt, uv):
    """World unit ray directions (N, M, 3) of pixels uv (M, 2); K_inv_Rt = R^T K^-1 (N, 3, 3)."""
    homog = torch.cat([uv, torch.ones_like(uv[:, :1])], -1)
    d = _apply(K_inv_Rt, homog.expand(K_inv_Rt.shape[0], *homog.shape))
    return d / d.norm(dim=-1, keepdim=True)


@dataclass(frozen=True)
class PairGeometry:
    """Spherical rectification of N view pairs (float64, no gradient).

    R_rect (N, 3, 3): rows = baseline x, y, z of the shared rectified frame (world -> rect).
    proj_i, proj_j (N, 3, 3): K R R_rect^T, rectified direction -> homogeneous heatmap pixel.
    theta_range (N, 2): epipolar-plane angles of the rows: with overlap=True (the
        divergence) those covered by both windows, else (display) by either window.
    alpha_i, alpha_j (N, 2): ray-to-baseline angles covered by each window (columns).
    rows_needed, cols_needed (N,): grid size for ``max_spacing`` at the window centres.
    valid (N,) bool: False for degenerate pairs.
    """

    R_rect: torch.Tensor
    proj_i: torch.Tensor
    proj_j: torch.Tensor
    theta_range: torch.Tensor
    alpha_i: torch.Tensor
    alpha_j: torch.Tensor
    rows_needed: torch.Tensor
    cols_needed: torch.Tensor
    valid: torch.Tensor

    def select(self, index):
        return PairGeometry(*(getattr(self, f)[index] for f in self.__dataclass_fields__))

    def grid_size(self, rows=None, cols=None, max_grid=64):
        """(rows, cols): given values, else the largest need over valid pairs, in [4, max_grid]."""
        if rows is not None and cols is not None:
            return int(rows), int(cols)
        if bool(self.valid.any()):
            need_r = math.ceil(float(self.rows_needed[self.valid].max()))
            need_c = math.ceil(float(self.cols_needed[self.valid].max()))
        else:
            need_r = need_c = 4
        rows = int(rows) if rows is not None else min(max(need_r, 4), max_grid)
        cols = int(cols) if cols is not None else min(max(need_c, 4), max_grid)
        return rows, cols

    def row_angles(self, rows):
        """(N, rows) epipolar-plane angle theta of each rectified row (pixel-centred bins)."""
        k = torch.arange(rows, dtype=self.theta_range.dtype, device=self.theta_range.device)
        lo, hi = self.theta_range[:, :1], self.theta_range[:, 1:]
        return lo + (k + 0.5) / rows * (hi - lo)

    @staticmethod
    def column_angles(alpha, cols):
        k = torch.arange(cols, dtype=alpha.dtype, device=alpha.device)
        return alpha[:, :1] + (k + 0.5) / cols * (alpha[:, 1:] - alpha[:, :1])


@torch.no_grad()
def pair_geometry(K_i, R_i, t_i, size_i, K_j, R_j, t_j, size_j, min_angle_deg=10.0,
                  max_spacing=1.0, overlap=True):
    """Shared rectified frame, windows and degeneracy flags of N pairs; K, R, t (N, ...).

    overlap: rows span the epipolar planes both windows see (a pair without any is invalid);
    a row only one window sees has nothing to compare with (zero padding in the other), so
    it would only add KL that no detection can remove. False: planes either window sees."""
    f64 = dict(dtype=torch.float64, device=K_i.device)
    K_i, R_i, t_i, K_j, R_j, t_j = (a.detach().to(**f64) for a in (K_i, R_i, t_i, K_j, R_j, t_j))
    n = K_i.shape[0]
    C_i = -_apply(R_i.transpose(-1, -2), t_i)
    C_j = -_apply(R_j.transpose(-1, -2), t_j)
    base = C_j - C_i
    length = base.norm(dim=-1)
    scale = torch.maximum(torch.maximum(C_i.norm(dim=-1), C_j.norm(dim=-1)),
                          torch.ones_like(length))
    separated = length > 1e-9 * scale

    back_i = _mm(R_i.transpose(-1, -2), torch.linalg.inv(K_i))
    back_j = _mm(R_j.transpose(-1, -2), torch.linalg.inv(K_j))
    border_i, border_j = _border_pixels(size_i, **f64), _border_pixels(size_j, **f64)
    centre_i = torch.tensor([[(size_i[1] - 1) / 2, (size_i[0] - 1) / 2]], **f64)
    centre_j = torch.tensor([[(size_j[1] - 1) / 2, (size_j[0] - 1) / 2]], **f64)
    step = torch.tensor([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], **f64)
    probe_i = _rays(back_i, centre_i + step)           # (N, 3, 3): centre, +u, +v
    probe_j = _rays(back_j, centre_j + step)

    # Shared frame (geometry.rectifying_rotation): x = baseline, z = mean optical axis made
    # orthogonal to it; NaN (-> identity, flagged) when degenerate.
    R_rect = rectifying_rotation(R_i, t_i, R_j, t_j)
    framed = torch.isfinite(R_rect).all(-1).all(-1)
    R_rect = torch.where(framed[:, None, None], R_rect, torch.eye(3, **f64).expand(n, 3, 3))

    cos_min = math.cos(math.radians(min_angle_deg))
    valid = separated & framed
    out = {}
    for tag, back, border, probe, K, R, size in (
            ('i', back_i, border_i, probe_i, K_i, R_i, size_i),
            ('j', back_j, border_j, probe_j, K_j, R_j, size_j)):
        d = _apply(R_rect, _rays(back, border))                  # (N, M, 3) rect coords
        theta = torch.atan2(d[..., 1], d[..., 2])
        alpha = torch.acos(d[..., 0].clamp(-1.0, 1.0))
        # Epipole (or its antipode) inside the window: some ray is parallel to the baseline.
        proj = _mm(_mm(K, R), R_rect.transpose(-1, -2))
        e = _apply(proj, torch.tensor([1.0, 0.0, 0.0], **f64).expand(n, 3))
        finite = e[:, 2].abs() > 1e-12 * e.norm(dim=-1)
        ez = torch.where(finite, e[:, 2], torch.ones_like(e[:, 2]))
        eu, ev = e[:, 0] / ez, e[:, 1] / ez
        inside = finite & (eu > -0.5) & (eu < size[1] - 0.5) & (ev > -0.5) & (ev < size[0] - 0.5)
        valid &= ~inside
        valid &= (d[..., 0].abs() <= cos_min).all(-1)             # rays >= min angle
        valid &= (d[..., 2] > 1e-6).all(-1)                       # |theta| < 90 degrees
        # Angular pixel pitch at the centre; a row step moves a ray by sin(alpha) dtheta.
        pc = _apply(R_rect, probe)
        cos_step = (pc[:, :1] * pc[:, 1:]).sum(-1).clamp(-1.0, 1.0)
        pitch = torch.acos(cos_step).amin(-1).clamp_min(1e-12)
        sin_c = pc[:, 0, 1:].norm(dim=-1).clamp_min(1e-12)
        out[tag] = dict(theta=(theta.amin(-1), theta.amax(-1)),
                        alpha=torch.stack([alpha.amin(-1), alpha.amax(-1)], -1),
                        d_alpha=0.5 * max_spacing * pitch, d_theta=max_spacing * pitch / sin_c,
                        proj=proj)
    pick_lo, pick_hi = (torch.maximum, torch.minimum) if overlap else (torch.minimum,
                                                                          torch.maximum)
    lo = pick_lo(out['i']['theta'][0], out['j']['theta'][0])
    hi = pick_hi(out['i']['theta'][1], out['j']['theta'][1])
    valid &= hi > lo
    theta_range = torch.stack([lo, hi], -1)
    rows_needed = (hi - lo) / torch.minimum(out['i']['d_theta'], out['j']['d_theta'])
    cols_needed = torch.maximum(
        (out['i']['alpha'][:, 1] - out['i']['alpha'][:, 0]) / out['i']['d_alpha'],
        (out['j']['alpha'][:, 1] - out['j']['alpha'][:, 0]) / out['j']['d_alpha'])
    dummy = torch.tensor([0.0, 1.0], **f64).expand(n, 2)
    keep = valid[:, None]
    return PairGeometry(
        R_rect=R_rect, proj_i=out['i']['proj'], proj_j=out['j']['proj'],
        theta_range=torch.where(keep, theta_range, dummy),
        alpha_i=torch.where(keep, out['i']['alpha'], dummy + 1.0),
        alpha_j=torch.where(keep, out['j']['alpha'], dummy + 1.0),
        rows_needed=torch.where(valid, rows_needed, torch.zeros_like(rows_needed)),
        cols_needed=torch.where(valid, cols_needed, torch.zeros_like(cols_needed)),
        valid=valid)


@torch.no_grad()
def _sampling_grid(proj, alpha, theta_k, valid, cols, size, dtype):
    """grid_sample grid (N, rows, cols, 2) of one view's rectified heatmap."""
    h, w = size
    a = PairGeometry.column_angles(alpha, cols)                  # (N, cols)
    # p = proj d, d = (cos a, sin a sin theta, sin a cos theta): (N, 3, rows, cols) in two
    # rank-1 terms, without materialising d.
    across = (proj[:, :, 1, None] * torch.sin(theta_k)[:, None]
              + proj[:, :, 2, None] * torch.cos(theta_k)[:, None])          # (N, 3, rows)
    p = (proj[:, :, 0, None, None] * torch.cos(a)[:, None, None]
         + across[..., None] * torch.sin(a)[:, None, None])                   # (N, 3, rows, cols)
    front = (p[:, 2] > 1e-9) & valid[:, None, None]
    z = torch.where(front, p[:, 2], torch.ones_like(p[:, 2]))
    gx = ((p[:, 0] / z + 0.5) * (2.0 / w) - 1.0).clamp(_OUTSIDE, -_OUTSIDE)
    gy = ((p[:, 1] / z + 0.5) * (2.0 / h) - 1.0).clamp(_OUTSIDE, -_OUTSIDE)
    grid = torch.stack([gx, gy], -1)
    return torch.where(front[..., None], grid, torch.full_like(grid, _OUTSIDE)).to(dtype)


@dataclass(frozen=True)
class RectifiedPair:
    """heat_i, heat_j (B, C, rows, cols): rectified heatmaps, row k = plane theta (B, rows)
    in both; R_rect (B, 3, 3) world -> rectified frame; valid (B,) bool."""

    heat_i: torch.Tensor
    heat_j: torch.Tensor
    theta: torch.Tensor
    R_rect: torch.Tensor
    valid: torch.Tensor


_SAMPLE = dict(mode='bilinear', padding_mode='zeros', align_corners=False)


def _grids(heat_i, heat_j, geom, rows, cols):
    theta_k = geom.row_angles(rows)
    grid_i = _sampling_grid(geom.proj_i, geom.alpha_i, theta_k, geom.valid, cols,
                            tuple(heat_i.shape[-2:]), heat_i.dtype)
    grid_j = _sampling_grid(geom.proj_j, geom.alpha_j, theta_k, geom.valid, cols,
                            tuple(heat_j.shape[-2:]), heat_j.dtype)
    return grid_i, grid_j, theta_k


def _sample_pair(heat_i, heat_j, grid_i, grid_j):
    """grid_sample of both views, one kernel call when the heatmap sizes agree."""
    if heat_i.shape[-2:] == heat_j.shape[-2:]:
        both = F.grid_sample(torch.cat([heat_i, heat_j]), torch.cat([grid_i, grid_j]),
                             **_SAMPLE)
        return both[:heat_i.shape[0]], both[heat_i.shape[0]:]
    return F.grid_sample(heat_i, grid_i, **_SAMPLE), F.grid_sample(heat_j, grid_j, **_SAMPLE)


def _rectify(heat_i, heat_j, geom, rows, cols):
    """Rectified heatmaps (N, C, rows, cols) of both views and the row angles (N, rows)."""
    grid_i, grid_j, theta_k = _grids(heat_i, heat_j, geom, rows, cols)
    return (*_sample_pair(heat_i, heat_j, grid_i, grid_j), theta_k)


def max_along_rows(heat, grid):
    """(N, C, rows): max over each grid row of bilinear samples of heat (N, C, H, W) at grid
    (N, rows, cols, 2) (grid_sample coordinates, zero padding); equals
    grid_sample(heat, grid).amax(-1), gradient included.

    The full grid is sampled without autograd; only each row's maximising sample is sampled
    again with autograd, so the backward pass touches rows instead of rows x cols samples
    (the max passes its gradient to that one sample anyway).
    """
    N, C = heat.shape[:2]
    rows, cols = grid.shape[1:3]
    with torch.no_grad():
        best = F.grid_sample(heat, grid, **_SAMPLE).argmax(dim=-1)      # (N, C, rows)
    best = best + cols * torch.arange(rows, device=best.device)       # index in rows * cols
    index = best.reshape(N, C * rows, 1).expand(N, C * rows, 2)
    points = grid.reshape(N, rows * cols, 2).gather(1, index)         # (N, C * rows, 2)
    picked = F.grid_sample(heat.reshape(N * C, 1, *heat.shape[-2:]),
                           points.reshape(N * C, rows, 1, 2), **_SAMPLE)
    return picked.reshape(N, C, rows)


def _row_max(heat_i, heat_j, geom, rows, cols):
    """Row maxima (N, C, rows) of both rectified views (rectify + amax(-1))."""
    grid_i, grid_j, _ = _grids(heat_i, heat_j, geom, rows, cols)
    if heat_i.shape[-2:] == heat_j.shape[-2:]:        # one pass for both views
        both = max_along_rows(torch.cat([heat_i, heat_j]), torch.cat([grid_i, grid_j]))
        return both[:heat_i.shape[0]], both[heat_i.shape[0]:]
    return max_along_rows(heat_i, grid_i), max_along_rows(heat_j, grid_j)


def _row_distribution(row_max):
    """Q (N, C, rows): row maxima clamped non-negative, normalised over rows (0 if empty)."""
    q = row_max.clamp_min(0.0)
    return q / q.sum(dim=-1, keepdim=True).clamp_min(1e-12)


def _kl(p, q, eps):
    return (p * (torch.log(p + eps) - torch.log(q + eps))).sum(-1).clamp_min(0.0)


def _prepare(heat_i, heat_j, K_i, R_i, t_i, K_j, R_j, t_j, rows, cols, eps, min_angle_deg,
             max_spacing, max_grid, overlap=True):
    if heat_i.dim() != 4 or heat_j.dim() != 4:
        raise ValueError(f'heat_i and heat_j must be (B, C, H, W), got {tuple(heat_i.shape)} '
                         f'and {tuple(heat_j.shape)}')
    if heat_i.shape[:2] != heat_j.shape[:2]:
        raise ValueError(f'heat_i {tuple(heat_i.shape)} and heat_j {tuple(heat_j.shape)} '
                         'differ in batch or keypoint count')
    _check_camera_batch('camera i', K_i, R_i, t_i, heat_i.shape[:1])
    _check_camera_batch('camera j', K_j, R_j, t_j, heat_j.shape[:1])
    _check_options(min_angle_deg, max_spacing, eps, rows, cols, max_grid)
    geom = pair_geometry(K_i, R_i, t_i, tuple(heat_i.shape[-2:]), K_j, R_j, t_j,
                         tuple(heat_j.shape[-2:]), min_angle_deg, max_spacing, overlap)
    max_grid = max_grid or 4 * max(*heat_i.shape[-2:], *heat_j.shape[-2:])
    return geom, geom.grid_size(rows, cols, max_grid)


def rectify_pair(heat_i, heat_j, K_i, R_i, t_i, K_j, R_j, t_j, *, rows=None, cols=None,
                 min_angle_deg=10.0, max_spacing=1.0, max_grid=None, overlap=False):
    """Rectify two heatmap batches (B, C, H, W) so that row k of both is epipolar plane k.

    K (B, 3, 3) in heatmap pixels, R (B, 3, 3), t (B, 3) world -> camera. rows, cols: grid
    size (default: from ``max_spacing`` heatmap pixels at the window centres, at most
    ``max_grid``, default 4 max(H, W)). overlap: rows = the planes both windows see (those
    the divergence compares); default False: every plane either window sees.
    Differentiable in the heatmaps.
    """
    geom, (rows, cols) = _prepare(heat_i, heat_j, K_i, R_i, t_i, K_j, R_j, t_j, rows, cols,
                                  1.0, min_angle_deg, max_spacing, max_grid, overlap)
    rect_i, rect_j, theta = _rectify(heat_i, heat_j, geom, rows, cols)
    return RectifiedPair(rect_i, rect_j, theta, geom.R_rect, geom.valid)


def epipolar_divergence(heat_i, heat_j, K_i, R_i, t_i, K_j, R_j, t_j, *, eps=1e-6, rows=None,
                        cols=None, min_angle_deg=10.0, max_spacing=1.0, max_grid=None,
                        return_valid=False):
    """KL(Q_i || Q_j->i) per pair and keypoint: (B, C) >= 0, differentiable in both heatmaps.

    heat_i, heat_j (B, C, H, W) non-negative heatmaps (negative values count as 0); K (B, 3, 3)
    in heatmap pixels; R (B, 3, 3), t (B, 3) world -> camera. Q(v) = max over row v of the
    rectified heatmap, normalised over the rows (epipolar planes) that both windows see;
    eps is added inside the logarithms. Degenerate pairs (and pairs without shared planes)
    give 0 (no gradient); with ``return_valid=True`` returns (divergence, valid (B,)).
    """
    geom, (rows, cols) = _prepare(heat_i, heat_j, K_i, R_i, t_i, K_j, R_j, t_j, rows, cols,
                                  eps, min_angle_deg, max_spacing, max_grid)
    max_i, max_j = _row_max(heat_i, heat_j, geom, rows, cols)
    div = _kl(_row_distribution(max_i), _row_distribution(max_j), eps)
    div = torch.where(geom.valid[:, None], div, torch.zeros_like(div))
    return (div, geom.valid) if return_valid else div


def _multiview_pairs(K, R, t, size, valid, min_angle_deg, max_spacing):
    """Geometry of all unordered pairs i < j; returns (b, i, j, geometry of those pairs)."""
    if K.dim() != 4 or K.shape[-2:] != (3, 3):
        raise ValueError(f'K must be (B, V, 3, 3), got {tuple(K.shape)}')
    B, V = K.shape[:2]
    _check_camera_batch('cameras', K, R, t, (B, V))
    if valid is not None:
        valid = torch.as_tensor(valid, device=K.device).to(torch.bool)
        if tuple(valid.shape) != (B, V):
            raise ValueError(f'valid must be (B, V) = {(B, V)}, got {tuple(valid.shape)}')
    ii, jj = torch.triu_indices(V, V, 1, device=K.device)
    P = ii.numel()

    def flat(a, idx):
        return a[:, idx].reshape(B * P, *a.shape[2:])
    geom = pair_geometry(flat(K, ii), flat(R, ii), flat(t, ii), size,
                         flat(K, jj), flat(R, jj), flat(t, jj), size, min_angle_deg,
                         max_spacing)
    ok = geom.valid.reshape(B, P)
    if valid is not None:
        ok = ok & valid[:, ii] & valid[:, jj]
    b, p = ok.nonzero(as_tuple=True)
    return b, ii[p], jj[p], geom.select(b * P + p)


def valid_view_pairs(K, R, t, heatmap_size, valid=None, *, min_angle_deg=10.0):
    """Non-degenerate unordered view pairs (i < j) of each instant.

    K (B, V, 3, 3) heatmap pixels, R (B, V, 3, 3), t (B, V, 3); heatmap_size (h, w); valid
    (B, V) bool views present (None = all). Skips coincident centres and pairs whose
    baseline is within ``min_angle_deg`` of a viewing ray of either window (epipole in or
    near the window). Returns (b, i, j) int64 tensors (N,).
    """
    _check_options(min_angle_deg, 1.0, 1.0, None, None, None)
    b, i, j, _ = _multiview_pairs(K, R, t, tuple(heatmap_size), valid, min_angle_deg, 1.0)
    return b, i, j


def line_weights(heat, K, R, t, pair_valid, parallel_deg=10.0):
    """Per-keypoint weights (B, V, V, C) of the ordered terms (view i, partner j).

    The epipolar line that partner j draws through keypoint c's expected position in view i
    (the detached peak of heat[b, i, c]) runs towards the epipole of C_j. Partners whose
    lines there lie within `parallel_deg` of each other constrain the same direction (the
    paper uses pairs whose expected epipolar lines are not parallel); they share one weight,
    1 / (number of such partners), so every distinct direction counts once per keypoint.
    heat (B, V, C, h, w); K (B, V, 3, 3) heatmap px; R, t world -> camera; pair_valid
    (B, V, V) bool. Weights are 0 where the pair is not valid; no gradient.
    """
    with torch.no_grad():
        B, V, C, h, w = heat.shape
        f64 = dict(dtype=torch.float64, device=heat.device)
        K, R, t = (a.detach().to(**f64) for a in (K, R, t))
        flat = heat.detach().reshape(B, V, C, h * w).argmax(-1)
        p = torch.stack([(flat % w).to(**f64), (flat // w).to(**f64)], -1)   # (B, V, C, 2)
        centres = -(R.transpose(-1, -2) @ t[..., None])[..., 0]               # (B, V, 3)
        # epipole of C_j in view i, homogeneous: K_i (R_i C_j + t_i)        (B, i, j, 3)
        cam = torch.einsum('bikl,bjl->bijk', R, centres) + t[:, :, None]
        e = torch.einsum('bikl,bijl->bijk', K, cam)
        d = e[:, :, :, None, :2] - p[:, :, None] * e[:, :, :, None, 2:]        # (B, i, j, C, 2)
        d = d / d.norm(dim=-1, keepdim=True).clamp_min(1e-12)
        cos = (d[:, :, :, None] * d[:, :, None]).sum(-1).abs()              # (B, i, j, j', C)
        near = (cos >= math.cos(math.radians(parallel_deg))) & pair_valid[:, :, None, :, None]
        count = near.sum(3).clamp_min(1).to(heat.dtype)                       # (B, i, j, C)
        return pair_valid[..., None].to(heat.dtype) / count


def multiview_epipolar_loss(heat, K, R, t, valid=None, *, eps=1e-6, rows=None, cols=None,
                            min_angle_deg=10.0, max_spacing=1.0, max_grid=None,
                            reduction='mean', parallel_deg=10.0):
    """L_E: epipolar divergence over all keypoints and ordered pairs of valid views.

    heat (B, V, C, h, w) non-negative heatmaps; K (B, V, 3, 3) in heatmap pixels; R (B, V, 3, 3),
    t (B, V, 3) world -> camera; valid (B, V) bool views present (None = all). Every
    non-degenerate unordered pair is rectified once (all pairs in one grid_sample call) and
    both directions KL(Q_i || Q_j->i), KL(Q_j || Q_i->j) are used, i.e. all ordered pairs, as
    in the paper's sum over each view's paired views. parallel_deg > 0: each term is weighted
    by line_weights (partners drawing near-parallel lines through a keypoint share one
    weight); 0 = every term weighs 1. reduction: weighted 'mean' over (ordered pair,
    keypoint) terms or weighted 'sum'. Returns a scalar (0, still attached to heat, if no
    valid pair).
    """
    if heat.dim() != 5:
        raise ValueError(f'heat must be (B, V, C, h, w), got {tuple(heat.shape)}')
    if reduction not in ('mean', 'sum'):
        raise ValueError(f"reduction must be 'mean' or 'sum', got {reduction!r}")
    if not 0.0 <= parallel_deg < 90.0:
        raise ValueError(f'parallel_deg must be in [0, 90), got {parallel_deg}')
    _check_options(min_angle_deg, max_spacing, eps, rows, cols, max_grid)
    if tuple(K.shape[:2]) != tuple(heat.shape[:2]):
        raise ValueError(f'K {tuple(K.shape)} does not match heat (B, V) {tuple(heat.shape[:2])}')
    size = tuple(heat.shape[-2:])
    b, i, j, geom = _multiview_pairs(K, R, t, size, valid, min_angle_deg, max_spacing)
    if b.numel() == 0:
        return heat.sum() * 0.0
    rows, cols = geom.grid_size(rows, cols, max_grid or 4 * max(size))
    max_i, max_j = _row_max(heat[b, i], heat[b, j], geom, rows, cols)
    q_i, q_j = _row_distribution(max_i), _row_distribution(max_j)
    terms = torch.cat([_kl(q_i, q_j, eps), _kl(q_j, q_i, eps)])            # (2N, C)
    if parallel_deg > 0:
        B, V = heat.shape[:2]
        pair_valid = torch.zeros(B, V, V, dtype=torch.bool, device=heat.device)
        pair_valid[b, i, j] = True
        pair_valid[b, j, i] = True
        weights = line_weights(heat, K, R, t, pair_valid, parallel_deg)
        weights = torch.cat([weights[b, i, j], weights[b, j, i]])          # (2N, C)
    else:
        weights = torch.ones_like(terms)
    total = (weights * terms).sum()
    return total / weights.sum() if reduction == 'mean' else total
