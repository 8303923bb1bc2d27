"""The symmetric expected epipolar distance: a diagnostic, KNOWN TO COLLAPSE as a loss.

It was L_E until issue 36. Both of its views get gradient, so it is met by any configuration
consistent with some 3D point (every keypoint stacked on the body's centroid scores as well
as the truth) and drags the right views towards the wrong ones; sharpening dominates it.
Kept for measurements (bench/epipolar_loss.py) and as a consistency score; the trainer's
L_E is the anchored, one-sided losses.epipolar_loss.
"""
import torch

from monet_ros.learning.losses import (
    HEAT_FLOOR,
    fundamental_matrices,
    heatmap_distribution,
    heatmap_moments,
    peak_contrast,
)

_MIN_WEIGHT = 1e-3       # weight of a term between two flat maps


def symmetric_epipolar_terms(outputs, K, R, t, valid=None, floor=HEAT_FLOOR, distribution=None,
                        sharpen=True):
    """Per (instant, view pair, keypoint) terms of symmetric_epipolar_loss; see there for the
    inputs.

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
        raise ValueError(f'symmetric_epipolar_loss: outputs must be (B, V, C, h, w), got '
                         f'{tuple(outputs.shape)}')
    B, V, C, h, w = outputs.shape
    for name, a, tail in (('K', K, (3, 3)), ('R', R, (3, 3)), ('t', t, (3,))):
        if tuple(a.shape) != (B, V, *tail):
            raise ValueError(f'symmetric_epipolar_loss: {name} must be {(B, V, *tail)}, got '
                             f'{tuple(a.shape)}')
    present = torch.ones(B, V, dtype=torch.bool, device=outputs.device)
    if valid is not None:
        valid = torch.as_tensor(valid, device=outputs.device)
        if tuple(valid.shape) != (B, V):
            raise ValueError(f'symmetric_epipolar_loss: valid must be {(B, V)}, got '
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


def symmetric_epipolar_loss(outputs, K, R, t, valid=None):
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
    return reduce_symmetric_terms(symmetric_epipolar_terms(outputs, K, R, t, valid), outputs)


def reduce_symmetric_terms(terms, outputs):
    """symmetric_epipolar_loss from symmetric_epipolar_terms' dict: the weighted mean of the
    distances over the used terms; 0 attached to `outputs` when no pair is used."""
    if not bool(terms['pair_used'].any()):
        return outputs.sum() * 0.0
    weight = terms['weight']
    return (weight * terms['distance']).sum() / weight.sum()
