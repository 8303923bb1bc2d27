"""Convolutional Pose Machine (Wei et al., CVPR 2016) as used by MONET: 5 stages, 368 -> 46.

Layout of the original: an image feature extractor at stride 8, stage 1 predicts belief
maps from the image features alone, every later stage refines from the same features
concatenated with the previous stage's beliefs, and every stage is supervised
(intermediate supervision: forward returns all stages). The original stages use 9x9 and
11x11 kernels to reach a receptive field that covers the whole 46x46 map; here each
stage uses a stack of dilated 3x3 convolutions (dilations 1, 2, 4, 8 -> +30 heatmap px
of receptive field per stage, so stage 2 already sees the whole map) at ~1/10 of the
FLOPs, with BatchNorm for training from scratch. No background channel: the output has
exactly C = num_keypoints channels.
"""
import torch
from torch import nn

from monet_ros.models.layers import ConvBNAct, Normalize


class CPMStage(nn.Module):
    """(B, cin, 46, 46) -> (B, C, 46, 46) beliefs: dilated 3x3 stack, 1x1, 1x1."""

    def __init__(self, cin, width, num_keypoints, dilations=(1, 2, 4, 8)):
        super().__init__()
        layers = [ConvBNAct(cin, width, 3, dilation=dilations[0])]
        layers += [ConvBNAct(width, width, 3, dilation=d) for d in dilations[1:]]
        layers += [ConvBNAct(width, width, 1)]
        self.body = nn.Sequential(*layers)
        self.head = nn.Conv2d(width, num_keypoints, 1)

    def forward(self, x):
        return self.head(self.body(x))


class CPM(nn.Module):
    """images (B, 3, 368, 368) float RGB in [0, 1] -> list of num_stages (B, C, 46, 46)."""

    architecture = 'cpm'
    # int options and their bounds (build_model and checkpoints check them; input_size
    # is a [H, W] pair, see models.registry.check_options)
    OPTION_RANGES = {'num_stages': (1, 12), 'width': (1, 1024)}

    def __init__(self, num_keypoints, num_stages=5, width=128, input_size=(368, 368)):
        super().__init__()
        if num_keypoints < 1:
            raise ValueError(f'CPM: num_keypoints must be >= 1, got {num_keypoints}')
        if num_stages < 1:
            raise ValueError(f'CPM: num_stages must be >= 1, got {num_stages}')
        if input_size[0] % 8 or input_size[1] % 8:
            raise ValueError(f'CPM: input_size must be a multiple of 8, got {input_size}')
        self.num_keypoints = num_keypoints
        self.input_size = tuple(input_size)
        self.heatmap_size = (input_size[0] // 8, input_size[1] // 8)
        self.normalize = Normalize()
        # Image features at stride 8 (368 -> 184 -> 92 -> 46).
        self.features = nn.Sequential(
            ConvBNAct(3, 32, 3, stride=2),
            ConvBNAct(32, 64, 3, stride=2),
            ConvBNAct(64, 64, 3),
            nn.MaxPool2d(2),
            ConvBNAct(64, width, 3),
            ConvBNAct(width, width, 3),
        )
        self.stages = nn.ModuleList(
            [CPMStage(width, width, num_keypoints)]
            + [CPMStage(width + num_keypoints, width, num_keypoints)
               for _ in range(num_stages - 1)])

    def forward(self, images):
        features = self.features(self.normalize(images))
        beliefs = [self.stages[0](features)]
        for stage in self.stages[1:]:
            beliefs.append(stage(torch.cat([features, beliefs[-1]], dim=1)))
        return beliefs
