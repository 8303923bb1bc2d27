"""Heatmap codec: Gaussian targets for 2D labels and sub-pixel peak decoding (batched).

Heatmap pixel (u, v) = column u, row v, with pixel centres on integers (the convention of
monet_ros.geometry: a heatmap is the image of a virtual camera K_heat = S K). Both
functions take torch tensors or numpy arrays and return the same kind.
"""
import numpy as np
import torch


def _as_tensor(x):
    if isinstance(x, torch.Tensor):
        return x, False
    return torch.as_tensor(np.asarray(x)), True


def labelled_mask(points):
    """points (B, C, 2), NaN = unlabelled -> (B, C) bool, True where both coordinates are finite.

    Use it to exclude unlabelled keypoints from the loss (their target maps are zero).
    """
    pts, was_numpy = _as_tensor(points)
    mask = torch.isfinite(pts).all(dim=-1)
    return mask.numpy() if was_numpy else mask


def render_heatmaps(points, size, sigma):
    """Gaussian target maps exp(-|x - p|^2 / (2 sigma^2)) (peak 1) at sub-pixel points.

    points: (B, C, 2) heatmap pixels (u, v); NaN (either coordinate) = unlabelled -> an all-zero
    map (mask it out of the loss with `labelled_mask(points)`). Points outside the map give the
    visible part of their Gaussian. size: (h, w). sigma: heatmap pixels (> 0).
    -> (B, C, h, w) float32 (float64 stays float64).
    """
    pts, was_numpy = _as_tensor(points)
    if pts.ndim != 3 or pts.shape[-1] != 2:
        raise ValueError(f'render_heatmaps: points must be (B, C, 2), got {tuple(pts.shape)}')
    if not sigma > 0:
        raise ValueError(f'render_heatmaps: sigma must be > 0, got {sigma}')
    h, w = size
    dtype = pts.dtype if pts.dtype == torch.float64 else torch.float32
    pts = pts.to(dtype)
    valid = torch.isfinite(pts).all(dim=-1)                       # (B, C)
    safe = torch.where(valid[..., None], pts, torch.zeros_like(pts))
    us = torch.arange(w, dtype=dtype, device=pts.device)
    vs = torch.arange(h, dtype=dtype, device=pts.device)
    # Separable Gaussian: (B, C, 1, w) * (B, C, h, 1).
    gu = torch.exp(-(us - safe[..., 0:1]) ** 2 / (2 * sigma ** 2))[..., None, :]
    gv = torch.exp(-(vs - safe[..., 1:2]) ** 2 / (2 * sigma ** 2))[..., :, None]
    heat = gu * gv * valid[..., None, None].to(dtype)
    return heat.numpy() if was_numpy else heat


def _vertex_offset(left, centre, right):
    """Vertex of the parabola through (-1, left), (0, centre), (1, right); 0 when not a maximum."""
    curvature = left - 2 * centre + right
    ok = curvature < 0
    offset = 0.5 * (left - right) / np.where(ok, curvature, 1)
    return np.where(ok, offset, 0).astype(left.dtype)


def decode_heatmaps(heatmaps, eps=1e-10):
    """Sub-pixel peaks: argmax, then a 3-point quadratic fit of log(heatmap) along u and v.

    The log-quadratic fit is exact for a Gaussian peak (the target shape). At the border the
    3-point window is moved inside the map. The refinement is limited to +-1 pixel around
    the argmax and skipped along an axis where the window is not a local maximum.
    heatmaps: (B, C, h, w), h, w >= 3.
    -> peaks (B, C, 2) float (u, v) heatmap pixels, confidence (B, C) = the maximum value
    (<= 0 for an empty map; its peak is then the plain argmax).
    Computed with numpy on the host (a torch tensor is read there and the results are
    returned as tensors on its device; no gradient): numpy's argmax and the few small
    per-peak operations cost a fraction of torch's per-call overhead in the fusion loop.
    """
    is_torch = isinstance(heatmaps, torch.Tensor)
    heat = heatmaps.detach().cpu().numpy() if is_torch else np.asarray(heatmaps)
    if heat.ndim != 4:
        raise ValueError(
            f'decode_heatmaps: heatmaps must be (B, C, h, w), got {tuple(heat.shape)}')
    b, c, h, w = heat.shape
    if h < 3 or w < 3:
        raise ValueError(f'decode_heatmaps: heatmaps must be at least 3x3, got {h}x{w}')
    dtype = np.float64 if heat.dtype == np.float64 else np.float32
    flat = heat.reshape(b * c, h * w).astype(dtype, copy=False)
    index = np.argmax(flat, axis=1)                                  # (BC,)
    confidence = np.take_along_axis(flat, index[:, None], axis=1)[:, 0]
    row, col = np.divmod(index, w)
    # 3-point windows centred at the argmax, moved inside the map at the border.
    col_c = np.clip(col, 1, w - 2)
    row_c = np.clip(row, 1, h - 2)
    floor = np.maximum(np.abs(confidence) * dtype(eps), dtype(eps))[:, None]
    steps = np.array([-1, 0, 1])
    u_idx = (row * w + col_c)[:, None] + steps                       # (BC, 3) along the row
    v_idx = (row_c[:, None] + steps) * w + col[:, None]              # (BC, 3) along the column
    # log of the 6 window values only (not of the whole map)
    with np.errstate(invalid='ignore', divide='ignore', over='ignore'):
        lu = np.log(np.maximum(np.take_along_axis(flat, u_idx, axis=1), floor))
        lv = np.log(np.maximum(np.take_along_axis(flat, v_idx, axis=1), floor))
        u = col_c.astype(dtype) + _vertex_offset(lu[:, 0], lu[:, 1], lu[:, 2])
        v = row_c.astype(dtype) + _vertex_offset(lv[:, 0], lv[:, 1], lv[:, 2])
    colf, rowf = col.astype(dtype), row.astype(dtype)
    u = np.minimum(np.maximum(u, colf - 1), colf + 1)
    v = np.minimum(np.maximum(v, rowf - 1), rowf + 1)
    empty = confidence <= 0
    u = np.where(empty, colf, u)
    v = np.where(empty, rowf, v)
    peaks = np.stack([u, v], axis=-1).reshape(b, c, 2)
    confidence = confidence.reshape(b, c)
    if is_torch:
        return (torch.from_numpy(peaks).to(heatmaps.device),
                torch.from_numpy(np.ascontiguousarray(confidence)).to(heatmaps.device))
    return peaks, confidence
