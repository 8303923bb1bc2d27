"""Training losses of MONET: L_L / L_B (masked heatmap MSE) and L_E (epipolar_loss).

objective = L_L + lambda_e L_E + lambda_p L_B   (the paper: lambda_e = 5, lambda_p = 1)

L_E here is epipolar_loss, the expected symmetric epipolar distance between the views' maps
read as distributions, not the paper's KL of row maxima (epipolar.epipolar_divergence, kept
as a public function): that KL falls as maps flatten, this one is lowest for sharp peaks on
consistent epipolar lines (measured side by side: bench/epipolar_loss.py).
"""
import torch

from monet_ros.models import render_heatmaps


def masked_heatmap_mse(stages, points, sigma):
    """Squared error to Gaussian heatmaps, summed over the stages (intermediate supervision,
    as CPM).

    stages: list of (B, C, h, w) predicted heatmaps; points: (B, C, 2) heatmap pixels with
    NaN where a keypoint is not labelled (its channel is masked out). Each stage's term is
    the squared error summed over the pixels of a heatmap and averaged over the labelled
    (sample, keypoint) heatmaps, like CPM's Euclidean loss (a sum over pixels), so that the
    paper's weights (lambda_e = 5 against this scale) apply. Returns a scalar (0, attached
    to the graph, when nothing is labelled).
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
    for stage in stages:
        err = (stage - target) ** 2 * weight
        total = total + err.sum() / count
    return total


def objective(terms, lambda_e, lambda_p, lambda_t=0.0, lambda_r=0.0):
    """L_L + lambda_e L_E + lambda_p L_B + lambda_t L_T + lambda_r L_R from a dict of present
    terms ('L', 'E', 'B', 'T', 'R'). A term of weight 0 is left out (not multiplied by 0: a
    non-finite value would still poison the sum), so a run with a weight of 0 is the exact
    control of the run with that term."""
    total = next(iter(terms.values())) * 0.0
    for key, weight in (('L', 1.0), ('E', lambda_e), ('B', lambda_p), ('T', lambda_t),
                        ('R', lambda_r)):
        if key in terms and weight != 0:
            total = total + weight * terms[key]
    return total


# ------------------------------------------------------------------------- L_E (new form)
# Share of each map's maximum subtracted before it is normalised to a distribution: L_L
# trains maps towards Gaussians of peak 1 on a background of 0, so what is below a tenth of
# the peak is background.
HEAT_FLOOR = 0.1
_EMPTY = 1e-6            # per pixel: an empty (no pixel above the floor) map becomes uniform
_MIN_WEIGHT = 1e-3       # weight of a term between two flat maps


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


def epipolar_loss_terms(outputs, K, R, t, valid=None, floor=HEAT_FLOOR, distribution=None,
                        sharpen=True):
    """Per (instant, view pair, keypoint) terms of epipolar_loss; see there for the inputs.

    Returns dict: 'distance' (B, P, C) RMS symmetric epipolar distance (heatmap px, with
    gradient), 'weight' (B, P, C) detached weights (0 for unused pairs), 'pairs' (P, 2) the
    unordered view pairs (i < j), 'pair_used' (B, P) bool, 'pairs_possible' (the pairs of
    views present). distribution: optional callable (..., h, w) -> distributions replacing
    heatmap_distribution (for comparisons, bench/epipolar_loss.py). sharpen (default
    True): the spread terms (each map's covariance across the lines) carry gradient, so the
    loss optimised is the loss reported and training does not flatten maps; False: the
    gradient only moves the maps' means (measured worse-behaved: maps flatten towards the
    crop centre and peak contrast falls, bench/results/accuracy.md)."""
    if outputs.dim() != 5:
        raise ValueError(f'epipolar_loss: outputs must be (B, V, C, h, w), got '
                         f'{tuple(outputs.shape)}')
    B, V, C, h, w = outputs.shape
    for name, a, tail in (('K', K, (3, 3)), ('R', R, (3, 3)), ('t', t, (3,))):
        if tuple(a.shape) != (B, V, *tail):
            raise ValueError(f'epipolar_loss: {name} must be {(B, V, *tail)}, got '
                             f'{tuple(a.shape)}')
    present = torch.ones(B, V, dtype=torch.bool, device=outputs.device)
    if valid is not None:
        valid = torch.as_tensor(valid, device=outputs.device)
        if tuple(valid.shape) != (B, V):
            raise ValueError(f'epipolar_loss: valid must be {(B, V)}, got '
                             f'{tuple(valid.shape)}')
        present = valid.to(torch.bool)
    ii, jj = torch.triu_indices(V, V, 1, device=outputs.device)
    p = distribution(outputs) if distribution else heatmap_distribution(outputs, floor)
    mean, cov = heatmap_moments(p)                                         # (B, V, C, ...)
    F, baseline = fundamental_matrices(K[:, ii], R[:, ii], t[:, ii],
                                       K[:, jj], R[:, jj], t[:, jj])       # (B, P, 3, 3)
    scale = torch.linalg.inv(R.detach().to(torch.float64)).matmul(
        t.detach().to(torch.float64)[..., None]).norm(dim=(-2, -1))      # |C| per view
    separated = baseline > 1e-9 * torch.maximum(scale[:, ii], scale[:, jj]).clamp_min(1.0)
    possible = present[:, ii] & present[:, jj]
    used = possible & separated
    # x = mu + delta, E[delta] = 0, views independent:
    # E[(x_j^T F x_i)^2] = e^2 + l_j^T S_j l_j + l_i^T S_i l_i + tr(F2 S_i F2^T S_j)
    ones = torch.ones_like(mean[..., :1])
    m_i = torch.cat([mean[:, ii], ones[:, ii]], -1)                        # (B, P, C, 3)
    m_j = torch.cat([mean[:, jj], ones[:, jj]], -1)
    S_i, S_j = cov[:, ii], cov[:, jj]                                      # (B, P, C, 2, 2)
    Fc = F[:, :, None]                                                     # (B, P, 1, 3, 3)
    l_j = (Fc @ m_i[..., None])[..., 0]                                    # line in view j
    l_i = (Fc.transpose(-1, -2) @ m_j[..., None])[..., 0]                  # line in view i
    e = (m_j * l_j).sum(-1)
    F2 = Fc[..., :2, :2]
    spread = ((l_j[..., None, :2] @ S_j @ l_j[..., :2, None])[..., 0, 0]
              + (l_i[..., None, :2] @ S_i @ l_i[..., :2, None])[..., 0, 0]
              + (F2 @ S_i @ F2.transpose(-1, -2) @ S_j).diagonal(dim1=-2, dim2=-1).sum(-1))
    expected = e * e + (spread if sharpen else spread.detach())
    # symmetric epipolar distance: the mean of the two point-to-line squared distances, the
    # line norms taken at the means (detached: they only set the units)
    inv = 0.5 * (1.0 / l_j[..., :2].detach().square().sum(-1).clamp_min(1e-300)
                 + 1.0 / l_i[..., :2].detach().square().sum(-1).clamp_min(1e-300))
    # beyond the window diagonal a distance says nothing more (and is not pulled on)
    sq = (expected * inv).clamp(1e-12, float(h * h + w * w))
    distance = sq.sqrt().to(outputs.dtype)
    contrast = peak_contrast(outputs)                                      # (B, V, C)
    # + _MIN_WEIGHT: flat maps (contrast 0) still count, a little, so that the weighted mean
    # is defined and a batch of flat maps scores their (large) spread, not 0
    weight = (contrast[:, ii] * contrast[:, jj] + _MIN_WEIGHT) * \
        used[..., None].to(outputs.dtype)
    return {'distance': distance, 'weight': weight, 'pairs': torch.stack([ii, jj], -1),
            'pair_used': used, 'pairs_possible': int(possible.sum())}


def epipolar_loss(outputs, K, R, t, valid=None):
    """L_E: expected epipolar distance between the views of each instant, lowest where the
    keypoints are right.

    outputs (B, V, C, h, w): the network's last-stage raw heatmaps of V views of B instants;
    K (B, V, 3, 3): intrinsics of the heatmap grid (px of the h x w output); R (B, V, 3, 3),
    t (B, V, 3): world -> camera; valid (B, V) bool: views present (None = all). Returns a
    scalar, differentiable in `outputs`.

    Each map becomes a distribution over its pixels (heatmap_distribution: relu(heat - 0.1
    max), normalised). For every unordered pair (i, j) of present views with distinct centres (all
    V (V - 1) / 2 pairs, batched; no pair is skipped: nothing is rectified, so an epipole in
    the window is no special case) and keypoint, with x_i, x_j drawn independently from the
    two distributions, the term is sqrt(E[d^2]) with d^2 the symmetric epipolar distance
    (the mean of the squared distances of x_j to the epipolar line of x_i and of x_i to that
    of x_j; Hartley & Zisserman sec. 11.4.3), computed in closed form from the maps' means
    and covariances (heatmap px), clipped at the window diagonal. E[d^2] = (distance of the
    means)^2 + the spread of both maps across the lines, so it is lowest for sharp peaks on
    consistent epipolar lines: a uniform floor, broadening, a shift off the line or a flat
    map all raise it (measured: bench/epipolar_loss.py). The MONET paper's KL between
    row-max distributions falls instead as maps flatten. Measured in training
    (bench/results/accuracy.md): it raises peak contrast, but on a weak detector it makes
    the views agree on the cheapest consistent answer, the crop centre, and costs accuracy
    against its exact control. Terms are weighted by the detached
    peak contrasts of the two maps (peak_contrast: a map the detector is unsure of pulls
    little; + 0.001) and averaged with those weights over the used (pair, keypoint) terms.
    0 (attached) if no pair is used.
    Errors: ValueError naming the argument whose shape is wrong.
    """
    return reduce_epipolar_terms(epipolar_loss_terms(outputs, K, R, t, valid), outputs)


def reduce_epipolar_terms(terms, outputs):
    """epipolar_loss from epipolar_loss_terms' dict: the weighted mean of the distances over
    the used terms; 0 attached to `outputs` when no pair is used."""
    if not bool(terms['pair_used'].any()):
        return outputs.sum() * 0.0
    weight = terms['weight']
    return (weight * terms['distance']).sum() / weight.sum()
