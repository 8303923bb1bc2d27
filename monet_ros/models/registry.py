"""One registry of detector architectures, built by name with the keypoint count."""
from monet_ros.models.cpm import CPM
from monet_ros.models.hourglass import StackedHourglass
from monet_ros.models.small import SmallNet

MODELS = {
    'cpm': CPM,
    'hourglass': StackedHourglass,
    'small': SmallNet,
}


def build_model(name, num_keypoints, **options):
    """A fresh (randomly initialised) detector.

    name: 'cpm' (368x368 -> 46x46, 5 stages), 'hourglass' (256 -> 64, 2 stacks) or
    'small' (256 -> 64, CPU real time). options: architecture keyword arguments
    (e.g. num_stages, width, num_stacks, features); they must be JSON-able, since
    checkpoints store them as metadata['model_options'] to rebuild the same network.
    The model has .input_size (H, W), .heatmap_size (h, w), .num_keypoints, .architecture
    and forward(images (B, 3, H, W) float RGB in [0, 1]) -> list of (B, C, h, w), one per
    stage; the last is the prediction.
    """
    if name not in MODELS:
        raise ValueError(f'unknown architecture {name!r}; expected one of {sorted(MODELS)}')
    if not isinstance(num_keypoints, int) or num_keypoints < 1:
        raise ValueError(f'num_keypoints must be a positive int, got {num_keypoints!r}')
    model = MODELS[name](num_keypoints, **options)
    model.model_options = dict(options)
    return model
