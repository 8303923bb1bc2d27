"""A small fast detector for CPU real time: 256x256 in, 64x64 heatmaps out.

Stride-4 stem (two strided 3x3 convs), one residual block at 64x64, a context branch at
32x32 (strided conv + dilated residual blocks), nearest upsampling added back to the
64x64 skip, a 3x3 fusion conv and a 1x1 head. About 0.6 GMAC per image. Returns a
one-element list so that every model has the same output type.
"""
from torch import nn
import torch.nn.functional as F

from monet_ros.models.layers import BasicResidual, ConvBNAct, Normalize


class SmallNet(nn.Module):
    """images (B, 3, 256, 256) float RGB in [0, 1] -> [(B, C, 64, 64)]."""

    architecture = 'small'
    # int options and their bounds (build_model and checkpoints check them; input_size
    # is a [H, W] pair, see models.registry.check_options)
    OPTION_RANGES = {'width': (1, 1024), 'context_blocks': (0, 64)}

    def __init__(self, num_keypoints, width=48, context_blocks=2, input_size=(256, 256)):
        super().__init__()
        if num_keypoints < 1:
            raise ValueError(f'small: num_keypoints must be >= 1, got {num_keypoints}')
        if input_size[0] % 8 or input_size[1] % 8:
            raise ValueError(f'small: input_size must be a multiple of 8, got {input_size}')
        self.num_keypoints = num_keypoints
        self.input_size = tuple(input_size)
        self.heatmap_size = (input_size[0] // 4, input_size[1] // 4)
        self.normalize = Normalize()
        self.stem = nn.Sequential(
            ConvBNAct(3, width // 2, 3, stride=2),
            ConvBNAct(width // 2, width, 3, stride=2),
            BasicResidual(width, width),
        )
        self.context = nn.Sequential(
            ConvBNAct(width, 2 * width, 3, stride=2),
            *[BasicResidual(2 * width, 2 * width, dilation=2 ** (i % 3))
              for i in range(context_blocks)],
            ConvBNAct(2 * width, width, 1),
        )
        self.fuse_conv = ConvBNAct(width, width, 3)
        self.head = nn.Conv2d(width, num_keypoints, 1)

    def forward(self, images):
        skip = self.stem(self.normalize(images))
        context = F.interpolate(self.context(skip), scale_factor=2, mode='nearest')
        return [self.head(self.fuse_conv(skip + context))]
