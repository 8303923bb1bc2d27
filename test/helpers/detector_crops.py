"""What the detector node's crops should be, computed by hand (independently of
monet_ros.crop_rule), and a small random-weight checkpoint to run it with."""
import numpy as np
import torch

from monet_ros.models import build_model, save_checkpoint
from monet_ros.skeleton import load_skeleton

INPUT = (96, 128)     # network input (H, W) -> heatmaps (24, 32)


def make_checkpoint(path, seed):
    """A small human14 network with seeded random weights at INPUT, saved to path."""
    torch.manual_seed(seed)
    model = build_model('small', 14, input_size=INPUT)
    save_checkpoint(path, model, {'keypoints': list(load_skeleton('human14').keypoints)})
    return path


def expected_box(box, aspect):
    """A box grown about its centre to width / height = aspect."""
    x0, y0, x1, y1 = box
    w, h = x1 - x0, y1 - y0
    w, h = max(w, h * aspect), max(h, w / aspect)
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    return cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2


def expected_K(K, box, out_w, out_h):
    """The crop camera's K (3, 3): box (x0, y0, x1, y1) in px resampled to out_w x out_h
    (pixel centres at integer coordinates)."""
    x0, y0, x1, y1 = box
    sx, sy = out_w / (x1 - x0), out_h / (y1 - y0)
    S = np.array([[sx, 0, (0.5 - x0) * sx - 0.5], [0, sy, (0.5 - y0) * sy - 0.5], [0, 0, 1]])
    return S @ K
