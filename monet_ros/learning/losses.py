"""Training losses of MONET: L_L / L_B (masked heatmap MSE), L_T and L_E (epipolar_loss).

objective = L_L + lambda_e L_E + lambda_p L_B (+ lambda_t L_T + lambda_r L_R)

L_E is epipolar_loss, the ANCHORED, one-sided epipolar term (issue 36): in every view pair the
less confident view's soft-argmax is pulled onto the epipolar line of the more confident
view's detached peak, with a robust (Cauchy) kernel, and only from anchors above a confidence
cut-off. The symmetric forms (the paper's KL of row maxima, epipolar.epipolar_divergence /
multiview_epipolar_loss, and the expected symmetric distance, symmetric_epipolar) are kept
as diagnostics: they are met by any configuration consistent with some 3D point and collapse
when trained (bench/results/accuracy.md).
"""
import math

import torch

from monet_ros.models import decode_heatmaps, render_heatmaps


def masked_heatmap_mse(stages, points, sigma, weights=None):
    """Squared error to Gaussian heatmaps, summed over the stages (intermediate supervision,
    as CPM).

    stages: list of (B, C, h, w) predicted heatmaps; points: (B, C, 2) heatmap pixels with
    NaN where a keypoint is not labelled (its channel is masked out). Each stage's term is
    the squared error summed over the pixels of a heatmap and averaged over the labelled
    (sample, keypoint) heatmaps, like CPM's Euclidean loss (a sum over pixels), so that the
    paper's weights (lambda_e = 5 against this scale) apply. Returns a scalar (0, attached
    to the graph, when nothing is labelled). weights (B, C) (optional, >= 0): each labelled
    heatmap's squared error times its weight (still averaged over the labelled count), e.g.
    the distilled labels' confidence (L_D).
    """
    if not stages:
        raise ValueError('masked_heatmap_mse: no stages')
    B, C, h, w = stages[-1].shape
    points = torch.as_tensor(points, dtype=torch.float32, device=stages[-1].device)
    if points.shape != (B, C, 2):
        raise ValueError(f'masked_heatmap_mse: points must be {(B, C, 2)}, got '
                         f'{tuple(points.shape)}')
    mask = torch.isfinite(points).all(dim=-1)                              # (B, C)
    target = render_heatmaps(points, (h, w), sigma)                        # (B, C, h, w)
    count = mask.sum()
    total = stages[-1].sum() * 0.0
    if count == 0:
        return total
    weight = mask[..., None, None].to(target.dtype)
    if weights is not None:
        w = torch.as_tensor(weights, dtype=target.dtype, device=target.device)
        if w.shape != (B, C):
            raise ValueError(f'masked_heatmap_mse: weights must be {(B, C)}, got '
                             f'{tuple(w.shape)}')
        weight = weight * torch.nan_to_num(w, nan=0.0)[..., None, None]
    for stage in stages:
        err = (stage - target) ** 2 * weight
        total = total + err.sum() / count
    return total


def objective(terms, lambda_e, lambda_p, lambda_t=0.0, lambda_r=0.0, lambda_d=0.0):
    """L_L + lambda_e L_E + lambda_p L_B + lambda_t L_T + lambda_r L_R + lambda_d L_D from a
    dict of present terms ('L', 'E', 'B', 'T', 'R', 'D'). A term of weight 0 is left out (not
    multiplied by 0: a non-finite value would still poison the sum), so a run with a weight of
    0 is the exact control of the run with that term."""
    total = next(iter(terms.values())) * 0.0
    for key, weight in (('L', 1.0), ('E', lambda_e), ('B', lambda_p), ('T', lambda_t),
                        ('R', lambda_r), ('D', lambda_d)):
        if key in terms and weight != 0:
            total = total + weight * terms[key]
    return total


# ------------------------------------------------------------------------- L_E (new form)
# Share of each map's maximum subtracted before it is normalised to a distribution: L_L
# trains maps towards Gaussians of peak 1 on a background of 0, so what is below a tenth of
# the peak is background.
HEAT_FLOOR = 0.1
_EMPTY = 1e-6            # per pixel: an empty (no pixel above the floor) map becomes uniform


def heatmap_distribution(heat, floor=HEAT_FLOOR):
    """(..., h, w) heatmaps -> (..., h, w) distributions over the pixels, each summing to 1:
    relu(heat - floor x max(heat)) + 1e-6, normalised.

    Scale free (a map times a > 0 gives the same distribution, gradient included: lowering a
    peak cannot sharpen it, an absolute floor would reward exactly that) but not shift
    invariant: a uniform offset raises the part above the floor, broadening it, so a floor
    scores worse. A map with no pixel above the floor (all <= 0) is uniform, the least
    certain distribution. Differentiable through the pixels above the floor and the max."""
    top = heat.amax(dim=(-2, -1), keepdim=True)
    p = (heat - floor * top).clamp_min(0.0) + _EMPTY
    return p / p.sum(dim=(-2, -1), keepdim=True)


def heatmap_moments(p):
    """Mean (..., 2) and covariance (..., 2, 2) of pixel-centre coordinates (u, v) (heatmap
    px) under distributions p (..., h, w); float64 (centred at the window centre first, so
    that the variance of a sharp peak does not cancel)."""
    h, w = p.shape[-2:]
    p = p.to(torch.float64)
    u = torch.arange(w, dtype=p.dtype, device=p.device) - (w - 1) / 2
    v = torch.arange(h, dtype=p.dtype, device=p.device) - (h - 1) / 2
    pu, pv = p.sum(-2), p.sum(-1)                                       # marginals
    mu, mv = (pu * u).sum(-1), (pv * v).sum(-1)
    cuu = (pu * u * u).sum(-1) - mu * mu
    cvv = (pv * v * v).sum(-1) - mv * mv
    cuv = (p * v[:, None] * u[None, :]).sum((-2, -1)) - mu * mv
    mean = torch.stack([mu + (w - 1) / 2, mv + (h - 1) / 2], -1)
    cov = torch.stack([torch.stack([cuu, cuv], -1), torch.stack([cuv, cvv], -1)], -2)
    return mean, cov


def soft_argmax(heat, floor=HEAT_FLOOR):
    """(..., h, w) heatmaps -> (..., 2) expected (u, v) heatmap px under
    heatmap_distribution (scale free, the part above `floor` x the map's maximum);
    differentiable, float64."""
    return heatmap_moments(heatmap_distribution(heat, floor))[0]


def temporal_difference_loss(points, points_next, epsilon):
    """L_T, the temporal-difference loss of Lightning Pose (Biderman et al., Nature Methods
    2024, "temporal loss"): mean over (N, C) of relu(|points_next - points| - epsilon), the
    frame-to-frame jumps beyond the motion `epsilon` allowed for free.

    points, points_next: (N, C, 2) of one view and keypoint at two consecutive frames, in
    one pixel frame (heatmap px); epsilon in the same px. Returns a scalar."""
    if points.shape != points_next.shape or points.shape[-1] != 2:
        raise ValueError(f'temporal_difference_loss: points must both be (N, C, 2), got '
                         f'{tuple(points.shape)} and {tuple(points_next.shape)}')
    jump = ((points_next - points) ** 2).sum(-1).add(1e-12).sqrt()     # finite gradient at 0
    return (jump - epsilon).clamp_min(0.0).mean()


def fundamental_matrices(K_i, R_i, t_i, K_j, R_j, t_j):
    """F (..., 3, 3) with x_j^T F x_i = 0 for the pixels (homogeneous) of one 3D point in views
    i and j (Hartley & Zisserman eq. 9.2: F = K_j^-T [t]_x R K_i^-1 with the relative pose R =
    R_j R_i^T, t = t_j - R t_i), scaled to unit Frobenius norm; float64. K in the pixels of
    the heatmap grid, R, t world -> camera. Also returns the baseline length (...) in m."""
    K_i, R_i, t_i, K_j, R_j, t_j = (a.detach().to(torch.float64)
                                    for a in (K_i, R_i, t_i, K_j, R_j, t_j))
    R = R_j @ R_i.transpose(-1, -2)
    t = t_j - (R @ t_i[..., None])[..., 0]
    zero = torch.zeros_like(t[..., 0])
    tx = torch.stack([torch.stack([zero, -t[..., 2], t[..., 1]], -1),
                      torch.stack([t[..., 2], zero, -t[..., 0]], -1),
                      torch.stack([-t[..., 1], t[..., 0], zero], -1)], -2)
    F = torch.linalg.inv(K_j).transpose(-1, -2) @ tx @ R @ torch.linalg.inv(K_i)
    norm = F.flatten(-2).norm(dim=-1)
    return F / norm.clamp_min(1e-300)[..., None, None], t.norm(dim=-1)


def peak_contrast(heat):
    """(...) detached max - median of each (..., h, w) map, clipped to [0, 1]: how sure the
    detector is (a map trained to a peak of 1 on 0 scores 1, a flat map 0)."""
    with torch.no_grad():
        flat = heat.detach().flatten(-2)
        return (flat.amax(-1) - flat.median(-1).values).clamp(0.0, 1.0)




# --------------------------------------------------------------- L_E: anchored, one-sided
# The anchors' default cut-off without a trainer to give L_R's: half the peak of 1 that L_L
# trains labelled maps towards.
ANCHOR_CONFIDENCE = 0.5
KERNEL_PX = 1.0          # Cauchy scale (heatmap px): quadratic below it, logarithmic beyond
# Two confident views agree when their peaks lie within this distance (heatmap px) of each
# other's epipolar lines; an anchor needs one that agrees and no more that disagree.
AGREEMENT_PX = 2.0


def _ordered_pairs(V, device):
    """(P, 2) long: every ordered pair (anchor a, target g) of V views, a != g."""
    a, g = torch.meshgrid(torch.arange(V, device=device), torch.arange(V, device=device),
                          indexing='ij')
    keep = a != g
    return torch.stack([a[keep], g[keep]], -1)


def _check_epipolar_inputs(outputs, K, R, t, valid):
    if outputs.dim() != 5:
        raise ValueError(f'epipolar_loss: outputs must be (B, V, C, h, w), got '
                         f'{tuple(outputs.shape)}')
    B, V = outputs.shape[:2]
    for name, a, tail in (('K', K, (3, 3)), ('R', R, (3, 3)), ('t', t, (3,))):
        if tuple(a.shape) != (B, V, *tail):
            raise ValueError(f'epipolar_loss: {name} must be {(B, V, *tail)}, got '
                             f'{tuple(a.shape)}')
    if valid is None:
        return torch.ones(B, V, dtype=torch.bool, device=outputs.device)
    valid = torch.as_tensor(valid, device=outputs.device)
    if tuple(valid.shape) != (B, V):
        raise ValueError(f'epipolar_loss: valid must be {(B, V)}, got {tuple(valid.shape)}')
    return valid.to(torch.bool)


def _agreeing_anchors(peaks, conf, candidate, F, separated, pairs, agreement_px):
    """(B, V, C) bool: the candidates (confident views) that anchor L_E.

    Two candidates agree when the symmetric epipolar distance of their peaks is below
    agreement_px. A candidate's support is its peak plus the peaks of the candidates that
    agree with it (a confidence-weighted inlier count of its agreeing set, as RANSAC's). It
    anchors when at least one candidate agrees with it and its support is above that of
    every candidate that disagrees with it: a confident view on a wrong peak (a left / right
    swap, a stray detection) anchors nothing, and of two self-consistent groups (e.g. views
    collapsed on one wrong point against views on the truth) the better supported wins.
    peaks (B, V, C, 2), conf (B, V, C) peak heights, candidate (B, V, C), F (B, P, 3, 3)
    anchor -> target fundamental matrices of the ordered pairs (P, 2), separated (B, P)."""
    a, g = pairs[:, 0], pairs[:, 1]
    ones = torch.ones_like(peaks[..., :1])
    x_a = torch.cat([peaks[:, a], ones[:, a]], -1)                         # (B, P, C, 3)
    x_g = torch.cat([peaks[:, g], ones[:, g]], -1)
    line_g = (F[:, :, None] @ x_a[..., None])[..., 0]
    line_a = (F[:, :, None].transpose(-1, -2) @ x_g[..., None])[..., 0]
    e = (x_g * line_g).sum(-1).abs()
    d = 0.5 * (e / line_g[..., :2].norm(dim=-1).clamp_min(1e-300)
               + e / line_a[..., :2].norm(dim=-1).clamp_min(1e-300))
    both = candidate[:, a] & candidate[:, g] & separated[..., None]        # (B, P, C)
    close = d < agreement_px
    agree, disagree = both & close, both & ~close
    B, V, C = candidate.shape
    weight = torch.where(candidate, conf, torch.zeros_like(conf))
    support = weight.clone()
    support.index_add_(1, a, torch.where(agree, weight[:, g], torch.zeros_like(d)))
    partners = torch.zeros(B, V, C, dtype=torch.int64, device=peaks.device)
    partners.index_add_(1, a, agree.to(torch.int64))
    rival = torch.where(disagree, support[:, g], torch.full_like(d, -1.0))
    best_rival = torch.full_like(support, -1.0).scatter_reduce_(
        1, a[None, :, None].expand_as(rival), rival, 'amax')
    return candidate & (partners >= 1) & (support > best_rival)


def anchored_epipolar_terms(outputs, K, R, t, valid=None, anchor_confidence=ANCHOR_CONFIDENCE,
                            kernel_px=KERNEL_PX, agreement_px=AGREEMENT_PX, floor=HEAT_FLOOR):
    """Per (instant, ordered view pair, keypoint) terms of epipolar_loss; inputs as there.

    Returns dict: 'distance' (B, P, C) signed distance (heatmap px of the target view, with
    gradient into the target only) of the target's soft-argmax to the epipolar line of the
    anchor's peak, 'rho' (B, P, C) the Cauchy kernel of it, 'weight' (B, P, C) detached (the
    anchor's peak, clipped to [0, 1]; 0 where the term is not used), 'pairs' (P, 2) the
    ordered (anchor, target) view pairs, 'used' (B, P, C) bool, 'confidence' (B, V, C) the
    maps' peaks (detached), 'anchors' (B, V, C) bool: the views that may anchor others.
    An anchor is a present view whose peak is at least anchor_confidence, that another such
    view agrees with (peaks within agreement_px heatmap px of each other's epipolar lines)
    and whose agreeing set outweighs that of every such view disagreeing with it
    (_agreeing_anchors). A term is used where both views are present, their centres differ,
    view a anchors and its peak is above view g's: gradient only into the less confident
    view of a pair (ties: no term; the most confident view of a keypoint gets none)."""
    present = _check_epipolar_inputs(outputs, K, R, t, valid)
    if not (math.isfinite(kernel_px) and kernel_px > 0):
        raise ValueError(f'epipolar_loss: kernel_px must be finite and > 0, got {kernel_px}')
    if not math.isfinite(anchor_confidence):
        raise ValueError(f'epipolar_loss: anchor_confidence must be finite, got '
                         f'{anchor_confidence}')
    if not (math.isfinite(agreement_px) and agreement_px > 0):
        raise ValueError(f'epipolar_loss: agreement_px must be finite and > 0, got '
                         f'{agreement_px}')
    B, V, C, h, w = outputs.shape
    pairs = _ordered_pairs(V, outputs.device)
    a, g = pairs[:, 0], pairs[:, 1]
    # the anchors: detached sub-pixel peaks (the detections fusion would use) and their height
    peaks, conf = decode_heatmaps(outputs.detach().float().reshape(B * V, C, h, w))
    peaks = peaks.reshape(B, V, C, 2).to(torch.float64)
    conf = conf.reshape(B, V, C).to(torch.float64)
    mean = soft_argmax(outputs, floor)                                    # (B, V, C, 2) f64
    F, baseline = fundamental_matrices(K[:, a], R[:, a], t[:, a], K[:, g], R[:, g], t[:, g])
    scale = torch.linalg.inv(R.detach().to(torch.float64)).matmul(
        t.detach().to(torch.float64)[..., None]).norm(dim=(-2, -1))      # |C| per view
    separated = baseline > 1e-9 * torch.maximum(scale[:, a], scale[:, g]).clamp_min(1.0)
    anchors = _agreeing_anchors(peaks, conf, present[..., None] & (conf >= anchor_confidence),
                                F, separated, pairs, agreement_px)
    used = ((present[:, a] & present[:, g] & separated)[..., None]
            & anchors[:, a] & (conf[:, a] > conf[:, g]))                   # (B, P, C)
    ones = torch.ones_like(peaks[..., :1])
    x_a = torch.cat([peaks[:, a], ones[:, a]], -1)                         # (B, P, C, 3)
    line = (F[:, :, None] @ x_a[..., None])[..., 0]                        # in the target
    line = line / line[..., :2].norm(dim=-1, keepdim=True).clamp_min(1e-300)
    x_g = torch.cat([mean[:, g], ones[:, g]], -1)
    distance = (line * x_g).sum(-1)
    # beyond the window diagonal a distance says nothing more
    diag = math.hypot(h, w)
    distance = distance.clamp(-diag, diag)
    c2 = kernel_px * kernel_px
    rho = 0.5 * c2 * torch.log1p(distance * distance / c2)
    weight = conf[:, a].clamp(0.0, 1.0) * used.to(conf.dtype)
    return {'distance': distance.to(outputs.dtype), 'rho': rho.to(outputs.dtype),
            'weight': weight.to(outputs.dtype), 'pairs': pairs, 'used': used,
            'confidence': conf.to(outputs.dtype), 'anchors': anchors}


def reduce_anchored_terms(terms, outputs):
    """epipolar_loss from anchored_epipolar_terms' dict: the anchor-weighted mean of the
    kernel over the used terms; 0 attached to `outputs` when none is used."""
    weight = terms['weight']
    total = weight.sum()
    if not bool(total > 0):
        return outputs.sum() * 0.0
    return (weight * terms['rho']).sum() / total


def epipolar_loss(outputs, K, R, t, valid=None, *, anchor_confidence=ANCHOR_CONFIDENCE,
                  kernel_px=KERNEL_PX, agreement_px=AGREEMENT_PX):
    """L_E, the anchored epipolar term (issue 36): each view is pulled onto the epipolar
    lines of the views more confident than it, never the other way.

    outputs (B, V, C, h, w): the network's last-stage raw heatmaps of V views of B instants;
    K (B, V, 3, 3): intrinsics of the heatmap grid (px of the h x w output); R (B, V, 3, 3),
    t (B, V, 3): world -> camera (any length unit: only the direction of the baseline
    matters); valid (B, V) bool: views present (None = all); anchor_confidence: the least
    heatmap peak a view needs to anchor others (the trainer passes L_R's cut-off: a share of
    the detector's peak on its labelled views); kernel_px: the Cauchy kernel's scale (heatmap
    px); agreement_px: how close (heatmap px, symmetric epipolar distance) two confident
    views' peaks must be to agree. Returns a scalar >= 0, differentiable in `outputs`
    (through the targets only).

    For every ordered pair (anchor a, target g) of present views with distinct centres and
    keypoint where view a anchors and its peak is above view g's (an anchor: a peak of at
    least anchor_confidence confirmed by another confident view, its agreeing set
    outweighing any disagreeing one's, so a confident wrong view, such as a left / right
    swap, anchors nothing and drags no view): the anchor's
    sub-pixel peak x_a (models.decode_heatmaps, detached: no gradient into the anchor) gives
    the epipolar line l = F x_a in the target (Hartley & Zisserman eq. 9.2), and the term is
    rho(d) = c^2 / 2 log(1 + d^2 / c^2), d the distance (heatmap px) of the target's
    soft-argmax (the part of the map above a tenth of its peak, normalised) to l: a Cauchy
    kernel, so a view that is far off (a wrong peak, an occlusion) is pulled gently and an
    anchor that is itself wrong cannot drag a view far. Terms are averaged with the anchor's
    peak (clipped to [0, 1]) as weight; 0 (attached) when no term is used.

    Why this form (issue 36, measured): the symmetric forms (the paper's KL of rectified
    row maxima, epipolar.multiview_epipolar_loss, and the expected symmetric distance,
    symmetric_epipolar) score every keypoint stacked on the body's centroid as well as the
    truth, reward sharpening more than correcting a view, and move accurate views towards
    poor ones (55% of their gradient lands on the views that were right). Here the anchor
    gets no gradient, the soft-argmax of a symmetric peak does not change when it sharpens
    (no reward for sharpening at a fixed mean), and a configuration collapsed onto a
    consistent wrong point is pulled back by any confident view. With one anchor a target is
    constrained to a line only; with two or more, to their lines' intersection.
    Errors: ValueError naming the argument whose shape or value is wrong.
    """
    return reduce_anchored_terms(anchored_epipolar_terms(
        outputs, K, R, t, valid, anchor_confidence, kernel_px, agreement_px), outputs)
