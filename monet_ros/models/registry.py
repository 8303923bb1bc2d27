"""One registry of detector architectures, built by name with the keypoint count."""
from monet_ros.models.cpm import CPM
from monet_ros.models.hourglass import StackedHourglass
from monet_ros.models.small import SmallNet

MODELS = {
    'cpm': CPM,
    'hourglass': StackedHourglass,
    'small': SmallNet,
}


MAX_INPUT_SIDE = 4096     # network input height/width in pixels


class OptionError(ValueError):
    """A model option of the wrong type or out of its bounds; `.option` names it."""

    def __init__(self, option, message):
        self.option = option
        self.message = message
        super().__init__(f'model option {option}: {message}')

    def __reduce__(self):
        # raised in a worker process: it must unpickle in the parent
        return type(self), (self.option, self.message)


def check_options(name, options):
    """Check build options against the architecture's OPTION_RANGES (ints, bools refused)
    and input_size (a pair of ints in 1..MAX_INPUT_SIDE); OptionError naming the first bad
    one, ValueError for an unknown architecture. Runs before any network is built."""
    if name not in MODELS:
        raise ValueError(f'unknown architecture {name!r}; expected one of {sorted(MODELS)}')
    ranges = MODELS[name].OPTION_RANGES
    for key, value in options.items():
        if key == 'input_size':
            if not isinstance(value, (list, tuple)) or len(value) != 2 or not all(
                    _is_int(v) and 1 <= v <= MAX_INPUT_SIDE for v in value):
                raise OptionError(key, f'must be a pair [H, W] of ints in 1..{MAX_INPUT_SIDE}, '
                                  f'got {str(value)[:60]}')
            continue
        if key not in ranges:
            raise OptionError(key, f'is not an option of {name!r} (expected '
                              f'{sorted(ranges) + ["input_size"]})')
        low, high = ranges[key]
        if not _is_int(value) or not low <= value <= high:
            raise OptionError(key, f'must be an int in {low}..{high}, got {str(value)[:60]}')


def _is_int(value):
    return isinstance(value, int) and not isinstance(value, bool)


def build_model(name, num_keypoints, **options):
    """A fresh (randomly initialised) detector.

    name: 'cpm' (368x368 -> 46x46, 5 stages), 'hourglass' (256 -> 64, 2 stacks) or
    'small' (256 -> 64, CPU real time). options: architecture keyword arguments
    (e.g. num_stages, width, num_stacks, features); they must be JSON-able, since
    checkpoints store them as metadata['model_options'] to rebuild the same network.
    Options are checked first (check_options: bounded ints, OptionError naming the option),
    so absurd sizes never allocate. The model has .input_size (H, W), .heatmap_size (h, w),
    .num_keypoints, .architecture and forward(images (B, 3, H, W) float RGB in [0, 1]) ->
    list of (B, C, h, w), one per stage; the last is the prediction.
    """
    check_options(name, options)
    if not _is_int(num_keypoints) or num_keypoints < 1:
        raise ValueError(f'num_keypoints must be a positive int, got {num_keypoints!r}')
    model = MODELS[name](num_keypoints, **options)
    model.model_options = dict(options)
    return model
