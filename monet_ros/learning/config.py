"""TrainConfig: every training setting in one frozen, validated dataclass (no ROS).

Flat scalar/tuple fields (monet_ros.config), so the learner node can mirror them as ROS
parameters and `monet train` as command-line options.
"""
from dataclasses import asdict, dataclass, fields, replace

from monet_ros.config import ConfigError, config_from_mapping, setting, validate_config
from monet_ros.learning.dataset import AugmentConfig
from monet_ros.learning.pseudo_labels import TrackingConfig

# Bounds that keep a typo from asking for an absurd allocation (input side in px, channel
# width, crops per step); far above anything the architectures are meant for.
MAX_INPUT_SIZE = 2048
MAX_WIDTH = 1024
MAX_BATCH = 4096

# The paper's rows (Table 1).
MODES = ('supervised', 'spatial', 'spatiotemporal', 'bootstrap1', 'bootstrap2', 'monet')


@dataclass(frozen=True)
class ModeSpec:
    """Which ingredients a mode uses: spatial / spatiotemporal pseudo-labels, bootstrapping
    rounds, epipolar divergence on unlabeled instants."""
    spatial: bool
    temporal: bool
    bootstrap_rounds: int
    epipolar: bool


MODE_SPECS = {
    'supervised': ModeSpec(False, False, 0, False),
    'spatial': ModeSpec(True, False, 0, False),
    'spatiotemporal': ModeSpec(True, True, 0, False),
    'bootstrap1': ModeSpec(True, False, 1, False),
    'bootstrap2': ModeSpec(True, False, 2, False),
    'monet': ModeSpec(True, False, 0, True),
}


@dataclass(frozen=True)
class TrainConfig:
    mode: str = setting('monet', "training mode (a row of the paper's Table 1)", choices=MODES)
    architecture: str = setting('small', 'detector architecture',
                                choices=('small', 'cpm', 'hourglass'))
    input_size: int = setting(0, "square network input side (px); 0 = the architecture's",
                              minimum=0, maximum=MAX_INPUT_SIZE)
    width: int = setting(0, "channel width of the small/cpm nets; 0 = the architecture's",
                         minimum=0, maximum=MAX_WIDTH)
    steps: int = setting(2000, 'training steps', minimum=1)
    batch_labelled: int = setting(8, 'labelled view crops per step', minimum=1,
                                  maximum=MAX_BATCH)
    batch_pseudo: int = setting(8, 'pseudo-labelled view crops per step', minimum=0,
                                maximum=MAX_BATCH)
    batch_unlabeled: int = setting(2, 'unlabeled instants per step (L_E)', minimum=0,
                                   maximum=MAX_BATCH)
    views_per_instant: int = setting(4, 'views of each unlabeled instant (L_E pairs)',
                                     minimum=2, maximum=64)
    lambda_e: float = setting(5.0, 'weight of the epipolar divergence L_E', minimum=0.0)
    lambda_p: float = setting(1.0, 'weight of the pseudo-label loss L_B', minimum=0.0)
    epipolar_warmup: float = setting(0.3, 'monet: fraction of the steps trained without L_E '
                                     '(L_L + L_B only) before the epipolar divergence starts',
                                     minimum=0.0, maximum=0.95)
    lr: float = setting(1e-4, 'Adam learning rate', minimum=0.0, exclusive_minimum=True)
    lr_decay: float = setting(0.9, 'learning-rate factor every lr_decay_every steps',
                              minimum=0.0, maximum=1.0, exclusive_minimum=True)
    lr_decay_every: int = setting(500, 'steps between learning-rate decays', minimum=1)
    sigma: float = setting(2.0, 'Gaussian target sigma (heatmap px)', minimum=0.0,
                           exclusive_minimum=True)
    checkpoint_every: int = setting(500, 'steps between checkpoints', minimum=1)
    seed: int = setting(0, 'random seed (sampling, augmentation, initialisation)', minimum=0)
    device: str = setting('auto', 'torch device: auto (CUDA when present), cpu, cuda, cuda:N')
    eval_fraction: float = setting(0.2, 'held-out tail of the recording (not trained on)',
                                   minimum=0.0, maximum=0.9)
    box_source: str = setting('auto', 'crop boxes: ground_truth, labels, full or auto',
                              choices=('auto', 'ground_truth', 'labels', 'full'))
    box_margin: float = setting(0.25, 'crop margin around the keypoints (fraction)',
                                minimum=0.0)
    cache_scale: float = setting(1.3, 'cached crop size / network crop (room to augment)',
                                 minimum=1.0)
    aug_scale: float = setting(0.15, 'crop scale jitter (fraction)', minimum=0.0, maximum=0.9)
    aug_translate: float = setting(0.08, 'crop shift jitter (fraction of side)', minimum=0.0)
    aug_rotate_deg: float = setting(15.0, 'in-plane rotation jitter (deg)', minimum=0.0,
                                    maximum=90.0)
    aug_photometric: float = setting(1.0, 'photometric jitter strength (0 = off)', minimum=0.0)
    bootstrap_confidence: float = setting(0.4, 'bootstrapping: minimum heatmap peak',
                                          minimum=0.0)
    bootstrap_threshold_px: float = setting(8.0, 'bootstrapping: RANSAC inlier threshold (px)',
                                            minimum=0.0, exclusive_minimum=True)
    bootstrap_min_views: int = setting(3, 'bootstrapping: minimum inlier views', minimum=2)
    monet_bootstrap_rounds: int = setting(
        2, "monet: bootstrapping rounds feeding L_B (the paper's bootstrapping prior; 2 = "
        "Bootstrapping II's); 0 = L_B on spatial pseudo-labels only", minimum=0, maximum=3)
    monet_temporal: bool = setting(
        False, 'monet: add spatiotemporal pseudo-labels (tracked, verified) to L_B; they take '
        'precedence over bootstrapped ones')
    track_horizon: int = setting(10, 'spatiotemporal: frames tracked each way', minimum=0)
    track_ransac_px: float = setting(4.0, 'spatiotemporal: RANSAC threshold (px)', minimum=0.0,
                                     exclusive_minimum=True)
    track_min_views: int = setting(3, 'spatiotemporal: minimum verified views', minimum=2)
    track_min_ncc: float = setting(0.7, 'spatiotemporal: minimum patch NCC', minimum=-1.0,
                                   maximum=1.0)

    def __post_init__(self):
        validate_config(self)
        if self.input_size and (self.input_size % 8 or self.input_size < 32):
            raise ConfigError('TrainConfig', 'input_size',
                              f'must be 0 or a multiple of 8 >= 32, got {self.input_size}')
        if self.width and self.width < 4:
            raise ConfigError('TrainConfig', 'width', f'must be 0 or >= 4, got {self.width}')
        if self.device not in ('auto', 'cpu', 'cuda') and not (
                self.device.startswith('cuda:') and self.device[5:].isdigit()):
            raise ConfigError('TrainConfig', 'device',
                              f'expected auto, cpu, cuda or cuda:N, got {self.device!r}')

    @property
    def spec(self):
        spec = MODE_SPECS[self.mode]
        if self.mode == 'monet':
            spec = replace(spec, bootstrap_rounds=self.monet_bootstrap_rounds,
                           temporal=self.monet_temporal)
        return spec

    @property
    def augment(self):
        p = self.aug_photometric
        return AugmentConfig(scale=self.aug_scale, translate=self.aug_translate,
                             rotate_deg=self.aug_rotate_deg, brightness=0.15 * p,
                             contrast=min(0.2 * p, 0.9), color=0.1 * p, noise=0.02 * p)

    @property
    def tracking(self):
        return TrackingConfig(horizon=self.track_horizon, ransac_px=self.track_ransac_px,
                              min_views=self.track_min_views, min_ncc=self.track_min_ncc)

    def model_options(self):
        """build_model keyword arguments from input_size / width (0 = default)."""
        options = {}
        if self.input_size:
            if self.architecture != 'small' and self.architecture != 'cpm':
                raise ConfigError('TrainConfig', 'input_size',
                                  f'not adjustable for {self.architecture}')
            options['input_size'] = [self.input_size, self.input_size]
        if self.width:
            options['width'] = self.width
        return options

    def to_dict(self):
        return asdict(self)

    @classmethod
    def from_dict(cls, values, source='<mapping>'):
        return config_from_mapping(cls, dict(values), source)


def config_fields():
    """(name, type, default, description) of every TrainConfig field (for CLIs and nodes)."""
    return [(f.name, f.type, f.default, f.metadata['description']) for f in fields(TrainConfig)]
