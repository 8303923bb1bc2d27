"""Building blocks shared by the detectors: conv+BN+ReLU, residual blocks, input normalisation.

Every convolution that is followed by a BatchNorm lives in a `ConvBNAct`, so that
`fuse_for_inference` can fold the BatchNorm into the convolution of an eval-mode copy.
"""
import torch
from torch import nn
from torch.nn.utils.fusion import fuse_conv_bn_eval

# Fixed input statistics (the usual natural-image RGB mean/std; constants, not learned or
# downloaded). Models take float images in [0, 1] and normalise inside forward, so every
# caller (trainer, detector, benchmarks) feeds the same thing.
RGB_MEAN = (0.485, 0.456, 0.406)
RGB_STD = (0.229, 0.224, 0.225)


class Normalize(nn.Module):
    """(B, 3, H, W) float RGB in [0, 1] -> (x - mean) / std (constants, not in the state_dict)."""

    def __init__(self, mean=RGB_MEAN, std=RGB_STD):
        super().__init__()
        self.register_buffer('mean', torch.tensor(mean).view(1, 3, 1, 1), persistent=False)
        self.register_buffer('std', torch.tensor(std).view(1, 3, 1, 1), persistent=False)

    def forward(self, x):
        return (x - self.mean) / self.std


class ConvBNAct(nn.Module):
    """Conv2d (no bias) -> BatchNorm2d -> ReLU (or no activation); 'same' padding."""

    def __init__(self, cin, cout, kernel=3, stride=1, dilation=1, act=True):
        super().__init__()
        padding = dilation * (kernel - 1) // 2
        self.conv = nn.Conv2d(cin, cout, kernel, stride, padding, dilation=dilation, bias=False)
        self.bn = nn.BatchNorm2d(cout)
        self.act = nn.ReLU(inplace=True) if act else nn.Identity()

    def forward(self, x):
        return self.act(self.bn(self.conv(x)))

    def fuse(self):
        """Fold the BatchNorm into the convolution (eval mode only)."""
        if isinstance(self.bn, nn.BatchNorm2d):
            self.conv = fuse_conv_bn_eval(self.conv, self.bn)
            self.bn = nn.Identity()


class BasicResidual(nn.Module):
    """Two 3x3 ConvBNAct with an identity (or 1x1 projection) shortcut: (B, C, H, W) same size."""

    def __init__(self, cin, cout, dilation=1):
        super().__init__()
        self.conv1 = ConvBNAct(cin, cout, 3, dilation=dilation)
        self.conv2 = ConvBNAct(cout, cout, 3, dilation=dilation, act=False)
        self.skip = nn.Identity() if cin == cout else ConvBNAct(cin, cout, 1, act=False)
        self.act = nn.ReLU(inplace=True)

    def forward(self, x):
        return self.act(self.conv2(self.conv1(x)) + self.skip(x))


class Bottleneck(nn.Module):
    """Hourglass residual module: 1x1 (cout/2) -> 3x3 (cout/2) -> 1x1 (cout) + shortcut."""

    def __init__(self, cin, cout):
        super().__init__()
        mid = cout // 2
        self.conv1 = ConvBNAct(cin, mid, 1)
        self.conv2 = ConvBNAct(mid, mid, 3)
        self.conv3 = ConvBNAct(mid, cout, 1, act=False)
        self.skip = nn.Identity() if cin == cout else ConvBNAct(cin, cout, 1, act=False)
        self.act = nn.ReLU(inplace=True)

    def forward(self, x):
        return self.act(self.conv3(self.conv2(self.conv1(x))) + self.skip(x))


def fuse_for_inference(model):
    """Fold every ConvBNAct's BatchNorm into its convolution, in place; returns the model.

    Only valid in eval mode (uses the running statistics); the fused model has a different
    state_dict, so it is marked `_fused = True` and save_checkpoint refuses it.
    """
    if model.training:
        raise ValueError('fuse_for_inference needs a model in eval mode (call model.eval())')
    for module in model.modules():
        if isinstance(module, ConvBNAct):
            module.fuse()
    model._fused = True
    return model
