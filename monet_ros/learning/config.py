"""TrainConfig: every training setting in one frozen, validated dataclass (no ROS).

Flat scalar/tuple fields (monet_ros.config), so the learner node can mirror them as ROS
parameters and `monet train` as command-line options.
"""
from dataclasses import asdict, dataclass, fields, replace

from monet_ros.config import ConfigError, config_from_mapping, setting, validate_config
from monet_ros.learning.dataset import AugmentConfig
from monet_ros.learning.pseudo_labels import TrackingConfig

# The paper's rows (Table 1), then ablations.
MODES = ('supervised', 'spatial', 'spatiotemporal', 'bootstrap1', 'bootstrap2', 'monet',
         'bootstrap2_epipolar')


@dataclass(frozen=True)
class ModeSpec:
    """Which ingredients a mode uses: spatial / spatiotemporal pseudo-labels, bootstrapping
    rounds, epipolar divergence on unlabeled instants."""
    spatial: bool
    temporal: bool
    bootstrap_rounds: int
    epipolar: bool


# As in the paper: Bootstrapping I / II start from the spatiotemporal augmentation, and
# MONET is L_L + lambda_e L_E + lambda_p L_B with L_B on the spatiotemporal augmentation.
# bootstrap2_epipolar (ablation): Bootstrapping II's labels from the spatial augmentation
# + L_E (this package's earlier `monet`).
MODE_SPECS = {
    'supervised': ModeSpec(False, False, 0, False),
    'spatial': ModeSpec(True, False, 0, False),
    'spatiotemporal': ModeSpec(True, True, 0, False),
    'bootstrap1': ModeSpec(True, True, 1, False),
    'bootstrap2': ModeSpec(True, True, 2, False),
    'monet': ModeSpec(True, True, 0, True),
    'bootstrap2_epipolar': ModeSpec(True, False, 2, True),
}


@dataclass(frozen=True)
class TrainConfig:
    mode: str = setting('monet', "training mode (a row of the paper's Table 1)", choices=MODES)
    architecture: str = setting('small', 'detector architecture',
                                choices=('small', 'cpm', 'hourglass'))
    input_size: int = setting(0, "square network input side (px); 0 = the architecture's",
                              minimum=0)
    width: int = setting(0, "channel width of the small/cpm nets; 0 = the architecture's",
                         minimum=0)
    steps: int = setting(2000, 'training steps', minimum=1)
    batch_labelled: int = setting(8, 'labelled view crops per step', minimum=1)
    batch_pseudo: int = setting(8, 'pseudo-labelled view crops per step', minimum=0)
    batch_unlabeled: int = setting(2, 'unlabeled instants per step (L_E)', minimum=0)
    views_per_instant: int = setting(4, 'views of each unlabeled instant (L_E pairs)',
                                     minimum=2)
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
    box_source: str = setting('auto', 'training crop boxes (monet_ros.crop_rule): auto = '
                              'pseudo_labels (labels + their spatiotemporal tracks), labels, '
                              'full, or ground_truth (benchmark option only)',
                              choices=('auto', 'pseudo_labels', 'labels', 'full',
                                       'ground_truth'))
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
        0, 'monet: bootstrapping rounds added to L_B (0 = the paper: L_B on the '
        'spatiotemporal augmentation only)', minimum=0, maximum=3)
    monet_temporal: bool = setting(
        True, "monet: L_B on the spatiotemporal augmentation (the paper's); false = spatial "
        'only')
    track_horizon: int = setting(50, 'spatiotemporal: frames tracked each way', minimum=0)
    track_ransac_px: float = setting(4.0, 'spatiotemporal: RANSAC threshold (px)', minimum=0.0,
                                     exclusive_minimum=True)
    track_min_views: int = setting(3, 'spatiotemporal: minimum verified views', minimum=2)
    track_min_ncc: float = setting(0.7, 'spatiotemporal: minimum patch NCC', minimum=-1.0,
                                   maximum=1.0)

    def __post_init__(self):
        validate_config(self)
        if self.input_size and self.input_size % 8:
            raise ConfigError('TrainConfig', 'input_size',
                              f'must be a multiple of 8, got {self.input_size}')
        if self.device != 'auto' and not (self.device == 'cpu' or
                                          self.device.startswith('cuda')):
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
