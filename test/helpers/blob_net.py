"""A small detector network trained (supervised, a few hundred steps, seconds on a CPU) to find
three coloured Gaussian blobs: the real trained model of the precision and decode tests."""
import numpy as np
import torch

from monet_ros.models import build_model
from monet_ros.models.detector import images_to_tensor
from monet_ros.models.heatmaps import render_heatmaps

NAMES = ['a', 'b', 'c']
SIZE = 64      # network input side (px); heatmaps are SIZE / 4
COLOURS = np.array([[255, 40, 40], [40, 255, 40], [60, 60, 255]], dtype=np.float64)


def blob_images(rng, n, size=SIZE, sigma=2.5, margin=8):
    """(n, size, size, 3) uint8 with one coloured Gaussian blob (sigma px) per keypoint on
    grey, and the blob centres (n, 3, 2) in pixels (pixel-centre convention). The net learns
    blobs of sigma 2.5 at SIZE: a frame `size` = k SIZE with sigma 2.5 k looks the same
    once cropped to SIZE. sigma (lo, hi): each image's sigma uniform in that range."""
    centres = rng.uniform(margin, size - margin, size=(n, len(NAMES), 2))
    if np.ndim(sigma):
        sigma = rng.uniform(*sigma, size=(n, 1, 1))
    yy, xx = np.mgrid[0:size, 0:size]
    images = np.full((n, size, size, 3), 70.0)
    for c in range(len(NAMES)):
        u, v = centres[:, c, 0, None, None], centres[:, c, 1, None, None]
        g = np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * sigma ** 2))[..., None]
        images = images * (1 - g) + COLOURS[c] * g
    return np.clip(images, 0, 255).astype(np.uint8), centres


def train_blob_net(steps=300, seed=0, sigma=2.5):
    """The small net (width 16, SIZE x SIZE input) trained on blob_images; eval mode. Trained
    on one torch thread: torch's thread count is process-wide and commands run earlier in
    the suite set it (`--threads`), and another count sums in another order, which over
    300 Adam steps gives another net (a test's tolerances would depend on test order).
    sigma: blob_images' (a (lo, hi) range: a net for blobs of several sizes)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return _train(steps, seed, sigma)
    finally:
        torch.set_num_threads(threads)


def _train(steps, seed, sigma):
    rng = np.random.default_rng(seed)
    torch.manual_seed(seed)
    model = build_model('small', len(NAMES), width=16, input_size=(SIZE, SIZE))
    optimiser = torch.optim.Adam(model.parameters(), lr=3e-3)
    for _ in range(steps):
        images, centres = blob_images(rng, 16, sigma=sigma)
        # heatmap pixel = (input pixel + 0.5) / 4 - 0.5 (pixel centres)
        target = render_heatmaps(torch.as_tensor((centres + 0.5) / 4 - 0.5),
                                 (SIZE // 4, SIZE // 4), 1.0)
        loss = ((model(images_to_tensor(images))[-1] - target.float()) ** 2).mean()
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    return model.eval()
