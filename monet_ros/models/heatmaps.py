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
    return np.where(ok, offset, 0).astype(left.dtype, copy=False)


_STEPS = np.array([-1, 0, 1])


def _window_index(index, wh):
    """Where the refinement reads each map: index (N,) flat argmax positions in maps of
    (w, h) = wh ((2,) for all maps or (N, 2) per map).
    -> idx (N, 7) flat positions of the argmax, of its 3-point window along u, then along v
    (each moved inside the map at the border); cr (N, 2) the argmax (col, row); cr_c (N, 2)
    the window centres."""
    w = wh[..., :1]
    row, col = np.divmod(index[:, None], w)
    cr = np.concatenate([col, row], axis=1)
    cr_c = np.minimum(np.maximum(cr, 1), wh - 2)
    idx = np.empty((len(index), 7), np.intp)
    idx[:, 0] = index
    idx[:, 1:4] = row * w + cr_c[:, :1] + _STEPS
    idx[:, 4:] = (cr_c[:, 1:] + _STEPS) * w + col
    return idx, cr, cr_c


def _refine_peaks(values, cr, cr_c, dtype, eps):
    """The sub-pixel step of decode_heatmaps. values (N, 7) of dtype: the maps at
    _window_index's idx; cr, cr_c (N, 2) from _window_index.
    -> peaks (N, 2) (u, v), confidence (N,) (the value at the argmax)."""
    confidence = np.ascontiguousarray(values[:, 0])
    floor = np.maximum(np.abs(confidence) * dtype(eps), dtype(eps))[:, None, None]
    # log of the 6 window values only (not of the whole map)
    with np.errstate(invalid='ignore', divide='ignore', over='ignore'):
        logs = np.log(np.maximum(values[:, 1:].reshape(-1, 2, 3), floor))
        peaks = cr_c.astype(dtype) + _vertex_offset(logs[..., 0], logs[..., 1], logs[..., 2])
    crf = cr.astype(dtype)
    peaks = np.minimum(np.maximum(peaks, crf - 1), crf + 1)
    return np.where((confidence <= 0)[:, None], crf, peaks), confidence


def _decode_dtype(dtype):
    return np.float64 if dtype == np.float64 else np.float32


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
    decode_heatmap_views decodes separate arrays the same way without stacking them.
    """
    is_torch = isinstance(heatmaps, torch.Tensor)
    heat = heatmaps.detach().cpu().numpy() if is_torch else np.asarray(heatmaps)
    if heat.ndim != 4:
        raise ValueError(
            f'decode_heatmaps: heatmaps must be (B, C, h, w), got {tuple(heat.shape)}')
    b, c, h, w = heat.shape
    if h < 3 or w < 3:
        raise ValueError(f'decode_heatmaps: heatmaps must be at least 3x3, got {h}x{w}')
    dtype = _decode_dtype(heat.dtype)
    flat = heat.reshape(b * c, h * w).astype(dtype, copy=False)
    index = np.argmax(flat, axis=1)                                  # (BC,)
    idx, cr, cr_c = _window_index(index, np.array([w, h]))
    peaks, confidence = _refine_peaks(np.take_along_axis(flat, idx, axis=1), cr, cr_c,
                                      dtype, eps)
    peaks = peaks.reshape(b, c, 2)
    confidence = confidence.reshape(b, c)
    if is_torch:
        return (torch.from_numpy(peaks).to(heatmaps.device),
                torch.from_numpy(confidence).to(heatmaps.device))
    return peaks, confidence


def _check_views(views, caller):
    """The views as arrays (V, C, h_v, w_v >= 3) and C; ValueError naming the bad view."""
    views = [np.asarray(view) for view in views]
    if not views:
        raise ValueError(f'{caller}: no views')
    grid = views[0].shape
    channels = grid[0] if len(grid) == 3 else None
    for v, view in enumerate(views):
        shape = view.shape
        if len(shape) != 3 or shape[0] != channels or shape[1] < 3 or shape[2] < 3:
            raise ValueError(f'{caller}: view {v} must be ({channels}, h, w) '
                             f'with h, w >= 3, got {shape}')
    return views, channels


def _argmax_views(views, channels):
    """One argmax per map of each view. -> (flats: V (C, h_v w_v) arrays in the decode
    dtype, index (V, C) argmax positions, finite (V,) bool, dtype)."""
    dtype = _decode_dtype(np.result_type(*views))
    count = len(views)
    index = np.empty((count, channels), np.intp)
    low = np.zeros(count)           # smallest value of each view: NaN or -inf shows there
    other = np.zeros(count, bool)   # neither float32 nor float64: checked as it is
    checked = np.ones(count, bool)
    flats = []
    for v, view in enumerate(views):
        flat = view.reshape(channels, view.shape[1] * view.shape[2])
        if view.dtype != np.float32 and view.dtype != np.float64:
            other[v] = True
            checked[v] = np.isfinite(view).all()
        elif view.size:
            low[v] = flat.min()
        if flat.dtype != dtype:
            flat = flat.astype(dtype)
        flat.argmax(axis=1, out=index[v])  # at the first NaN if any: its value shows it
        flats.append(flat)
    return flats, index, (checked & np.isfinite(low), other), dtype


def _finite(checks, confidence):
    """(V,) bool: no NaN / inf in the view. checks: _argmax_views'; confidence (V, C) at
    the argmax (a NaN shows there in a float view; another view was checked as it is)."""
    good, other = checks
    return good & (other | np.isfinite(confidence).all(axis=1))


def _refine_views(views, flats, index, dtype, eps):
    """Sub-pixel refinement of the maps at flat positions index (V, C, k) of every view.
    -> peaks (V, C, k, 2), confidence (V, C, k) (decode_heatmaps' step)."""
    count, channels, k = index.shape
    grid = views[0].shape
    if all(view.shape == grid for view in views):
        wh = np.array(grid[:0:-1])                                         # (w, h)
        offset = np.arange(channels)[:, None] * (grid[1] * grid[2])        # (C, 1)
        offset = np.repeat(offset, k, axis=0)                              # (C k, 1)
    else:
        wh = np.array([view.shape[:0:-1] for view in views])               # (V, 2)
        offset = np.arange(channels)[:, None] * wh.prod(axis=1)[:, None, None]
        offset = np.repeat(offset, k, axis=1)                              # (V, C k, 1)
        wh = np.repeat(wh, channels * k, axis=0)
    idx, cr, cr_c = _window_index(index.reshape(-1), wh)
    # positions in each view's (C * h * w) buffer: the channel's offset + the map's
    idx = idx.reshape(count, channels * k, 7) + offset
    values = np.empty((count, channels * k, 7), dtype)
    for v, flat in enumerate(flats):
        flat.take(idx[v], out=values[v], mode='clip')  # (in range: no buffering)
    peaks, confidence = _refine_peaks(values.reshape(-1, 7), cr, cr_c, dtype, eps)
    return peaks.reshape(count, channels, k, 2), confidence.reshape(count, channels, k)


def decode_heatmap_views(views, eps=1e-10):
    """decode_heatmaps of V separate numpy arrays (C, h_v, w_v), without stacking them.

    views: V arrays with the same C (grids may differ, h_v, w_v >= 3); the maps are not
    copied (only cast, when neither float32 nor float64). One argmax per view, then one
    batched refinement over every view, the same as decode_heatmaps': with equal grids the
    results equal decode_heatmaps(np.stack(views)) exactly (computed in float64 when
    np.result_type of the views is float64, otherwise in float32).
    -> peaks (V, C, 2) (u, v) heatmap pixels, confidence (V, C), finite (V,) bool: False
    where a view holds a NaN or an infinite value (its peaks then mean nothing).
    Raises ValueError naming the view whose shape does not fit.
    """
    views, channels = _check_views(views, 'decode_heatmap_views')
    flats, index, checks, dtype = _argmax_views(views, channels)
    peaks, confidence = _refine_views(views, flats, index[..., None], dtype, eps)
    return peaks[:, :, 0], confidence[:, :, 0], _finite(checks, confidence[:, :, 0])


def _other_maxima(flat, first, w, h, k, floor):
    """Flat positions (C, k - 1) of the k - 1 highest local maxima of each map of one
    view other than its argmax `first` (C,), among the pixels >= floor and > 0; -1 where a
    map has fewer. A local maximum is >= its 8 neighbours (the border replicated); only
    the pixels above the floor are tested (a few blobs, not the whole map)."""
    channels = flat.shape[0]
    out = np.full((channels, k - 1), -1, np.intp)
    # (flatnonzero of the 1D buffer: a few times faster than a 2D nonzero)
    at = np.flatnonzero(flat >= floor if floor > 0 else flat > 0)
    ch, pix = np.divmod(at, flat.shape[1])
    keep = pix != first[ch]
    at, ch, pix = at[keep], ch[keep], pix[keep]
    if not ch.size:
        return out
    buffer = flat.reshape(-1)
    value = buffer[at]
    # >= the left and right neighbours first (cheap, leaves about one pixel per blob row),
    # then >= the 3x3 window (the border replicated; the centre is compared with itself)
    row, col = np.divmod(pix, w)
    base = at - col
    side = (value >= buffer[base + np.maximum(col - 1, 0)]) \
        & (value >= buffer[base + np.minimum(col + 1, w - 1)])
    at, ch, pix, row, col, value = (a[side] for a in (at, ch, pix, row, col, value))
    rows = np.minimum(np.maximum(row[:, None] + _STEPS, 0), h - 1) * w       # (M, 3)
    cols = np.minimum(np.maximum(col[:, None] + _STEPS, 0), w - 1)           # (M, 3)
    window = (at - pix)[:, None, None] + rows[:, :, None] + cols[:, None, :]  # (M, 3, 3)
    peak = (value[:, None] >= buffer.take(window.reshape(len(at), 9))).all(axis=1)
    ch, pix, value = ch[peak], pix[peak], value[peak]
    order = np.lexsort((pix, -value, ch))    # per map: highest first, then lowest index
    ch, pix = ch[order], pix[order]
    starts = np.searchsorted(ch, ch)          # first entry of each map in the sorted list
    rank = np.arange(ch.size) - starts
    keep = rank < k - 1
    out[ch[keep], rank[keep]] = pix[keep]
    return out


def decode_heatmap_peaks(views, k, floor=0.0, channels=None, eps=1e-10):
    """The k highest local maxima of every map, each refined as decode_heatmaps' peak.

    views: V numpy arrays (C, h_v, w_v) (as decode_heatmap_views); k >= 1 candidates per
    map; floor: the local maxima below it (or <= 0) are not reported (fusion passes its
    confidence_threshold: weaker candidates would be ignored anyway, and only the pixels
    above it are searched, so the cost follows the blobs, not the map size); channels:
    indices (C',) of the maps to decode (default all; the fusion retries a few).
    Candidate 0 is the argmax, exactly decode_heatmap_views' peak and confidence (at any
    floor); candidates 1..k-1 are the other pixels >= their 8 neighbours, highest first.
    -> peaks (V, C, k, 2) (u, v) heatmap pixels, NaN where a map has fewer candidates;
    confidence (V, C, k), 0 there; finite (V,) bool as decode_heatmap_views' (C = C' with
    channels given: of those maps only).
    Raises ValueError for k < 1 or a view whose shape does not fit.
    """
    if int(k) != k or k < 1:
        raise ValueError(f'decode_heatmap_peaks: k must be an integer >= 1, got {k}')
    k = int(k)
    views, count = _check_views(views, 'decode_heatmap_peaks')
    if channels is not None:
        views = [view[np.asarray(channels, np.intp)] for view in views]   # (a small copy)
        count = len(channels)
    channels = count
    flats, first, checks, dtype = _argmax_views(views, channels)
    index = np.empty((len(views), channels, k), np.intp)
    index[:, :, 0] = first
    for v, (view, flat) in enumerate(zip(views, flats)):
        if k > 1:
            index[v, :, 1:] = _other_maxima(flat, first[v], view.shape[2], view.shape[1], k,
                                            floor)
    missing = index < 0
    index[missing] = np.broadcast_to(first[..., None], index.shape)[missing]
    peaks, confidence = _refine_views(views, flats, index, dtype, eps)
    finite = _finite(checks, confidence[:, :, 0])
    peaks[missing] = np.nan
    confidence[missing] = 0
    return peaks, confidence, finite
