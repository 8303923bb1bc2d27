"""Training losses of MONET: L_L / L_B (masked heatmap MSE) and L_E (epipolar divergence).

objective = L_L + lambda_e L_E + lambda_p L_B   (the paper: lambda_e = 5, lambda_p = 1)
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


def objective(terms, lambda_e, lambda_p):
    """L_L + lambda_e L_E + lambda_p L_B from a dict of present terms ('L', 'E', 'B')."""
    zero = next(iter(terms.values())) * 0.0
    return terms.get('L', zero) + lambda_e * terms.get('E', zero) + \
        lambda_p * terms.get('B', zero)
