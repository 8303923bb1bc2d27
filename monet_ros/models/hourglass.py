"""Stacked Hourglass (Newell et al., ECCV 2016): 256x256 in, 64x64 heatmaps per stack.

Stem at stride 4 (7x7 conv, residuals, max-pool), then `num_stacks` hourglasses of
bottleneck residual modules (depth 4: 64 -> 32 -> 16 -> 8 -> 4 and back, skip branches
added after nearest upsampling), each followed by a heatmap head; the intermediate
heatmaps are remapped into the features of the next stack, and every stack's heatmaps are
returned (intermediate supervision).
"""
from torch import nn
import torch.nn.functional as F

from monet_ros.models.layers import Bottleneck, ConvBNAct, Normalize


class Hourglass(nn.Module):
    """(B, F, H, W) -> (B, F, H, W); H and W divisible by 2**depth."""

    def __init__(self, depth, features):
        super().__init__()
        self.up1 = Bottleneck(features, features)
        self.low1 = Bottleneck(features, features)
        self.low2 = Hourglass(depth - 1, features) if depth > 1 else Bottleneck(features,
                                                                                 features)
        self.low3 = Bottleneck(features, features)

    def forward(self, x):
        low = self.low3(self.low2(self.low1(F.max_pool2d(x, 2))))
        return self.up1(x) + F.interpolate(low, scale_factor=2, mode='nearest')


class StackedHourglass(nn.Module):
    """images (B, 3, 256, 256) float RGB in [0, 1] -> list of num_stacks (B, C, 64, 64)."""

    architecture = 'hourglass'
    # int options and their bounds (build_model and checkpoints check them; input_size
    # is a [H, W] pair, see models.registry.check_options)
    OPTION_RANGES = {'num_stacks': (1, 8), 'features': (1, 1024), 'depth': (1, 6)}

    def __init__(self, num_keypoints, num_stacks=2, features=256, depth=4,
                 input_size=(256, 256)):
        super().__init__()
        if num_keypoints < 1:
            raise ValueError(f'hourglass: num_keypoints must be >= 1, got {num_keypoints}')
        if num_stacks < 1:
            raise ValueError(f'hourglass: num_stacks must be >= 1, got {num_stacks}')
        if input_size[0] % (4 << depth) or input_size[1] % (4 << depth):
            raise ValueError(
                f'hourglass: input_size must be a multiple of {4 << depth}, got {input_size}')
        self.num_keypoints = num_keypoints
        self.input_size = tuple(input_size)
        self.heatmap_size = (input_size[0] // 4, input_size[1] // 4)
        self.normalize = Normalize()
        half = features // 2
        self.stem = nn.Sequential(
            ConvBNAct(3, 64, 7, stride=2),
            Bottleneck(64, half),
            nn.MaxPool2d(2),
            Bottleneck(half, half),
            Bottleneck(half, features),
        )
        self.hourglasses = nn.ModuleList(Hourglass(depth, features) for _ in range(num_stacks))
        self.post = nn.ModuleList(
            nn.Sequential(Bottleneck(features, features), ConvBNAct(features, features, 1))
            for _ in range(num_stacks))
        self.heads = nn.ModuleList(nn.Conv2d(features, num_keypoints, 1)
                                   for _ in range(num_stacks))
        self.remap_features = nn.ModuleList(nn.Conv2d(features, features, 1)
                                            for _ in range(num_stacks - 1))
        self.remap_heatmaps = nn.ModuleList(nn.Conv2d(num_keypoints, features, 1)
                                            for _ in range(num_stacks - 1))

    def forward(self, images):
        x = self.stem(self.normalize(images))
        outputs = []
        for k, hourglass in enumerate(self.hourglasses):
            y = self.post[k](hourglass(x))
            heat = self.heads[k](y)
            outputs.append(heat)
            if k < len(self.hourglasses) - 1:
                x = x + self.remap_features[k](y) + self.remap_heatmaps[k](heat)
        return outputs
