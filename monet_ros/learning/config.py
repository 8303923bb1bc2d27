"""TrainConfig: every training setting in one frozen, validated dataclass (no ROS).

Flat scalar/tuple fields (monet_ros.config), so the learner node can mirror them as ROS
parameters and `monet train` as command-line options.
"""
from dataclasses import asdict, dataclass, fields, replace
import math

from monet_ros.config import ConfigError, config_from_mapping, setting, validate_config
from monet_ros.learning.dataset import AugmentConfig
from monet_ros.learning.pseudo_labels import TrackingConfig
from monet_ros.models.detector import PRECISIONS

# Bounds that keep a typo from asking for an absurd allocation (input side in px, channel
# width, crops per step); far above anything the architectures are meant for.
MAX_INPUT_SIZE = 2048
MAX_WIDTH = 1024
MAX_BATCH = 4096

# The paper's rows (Table 1), then ablations.
MODES = ('supervised', 'spatial', 'spatiotemporal', 'bootstrap1', 'bootstrap2', 'monet',
         'bootstrap2_epipolar', 'epipolar', 'temporal_difference', 'reprojection',
         'reprojection_epipolar')
# The loss terms a step can have: L_L, L_E, L_B, L_T, L_R, L_D (learning.losses.objective).
LOSS_TERMS = ('L', 'E', 'B', 'T', 'R', 'D')
# most distillation rounds (each runs the detector over the recording and trains on)
MAX_DISTILL_ROUNDS = 5
# the settings of the distillation rounds: used only with distill_rounds >= 1
DISTILL_SETTINGS = ('distill_steps', 'batch_distill', 'lambda_d', 'distill_gate_px',
                    'distill_min_views', 'distill_residual_px')
# the weight of each loss term on pseudo-labels or unlabeled instants (LOSS_TERMS)
TERM_WEIGHTS = {'B': 'lambda_p', 'E': 'lambda_e', 'T': 'lambda_t', 'R': 'lambda_r',
                'D': 'lambda_d'}


@dataclass(frozen=True)
class ModeSpec:
    """Which ingredients a mode uses: spatial / spatiotemporal pseudo-labels, bootstrapping
    rounds, and the losses on unlabeled instants: the anchored epipolar term L_E, temporal
    difference L_T (consecutive frames), reprojection consistency L_R (triangulate-reproject
    targets)."""
    spatial: bool
    temporal: bool
    bootstrap_rounds: int
    epipolar: bool
    temporal_difference: bool = False
    reprojection: bool = False

    @property
    def unlabeled(self):
        """The mode trains on unlabeled instants (the batch plan's part for them)."""
        return self.epipolar or self.temporal_difference or self.reprojection

    @property
    def uses_pseudo(self):
        """The mode trains L_B (spatial / spatiotemporal / bootstrapped pseudo-labels)."""
        return self.spatial or self.temporal or self.bootstrap_rounds > 0

    @property
    def terms(self):
        """The loss terms of the mode (LOSS_TERMS, L_D apart: distillation rounds add it to
        any mode), e.g. ('L', 'B', 'R')."""
        return tuple(t for t, on in (('L', True), ('B', self.uses_pseudo),
                                     ('E', self.epipolar), ('T', self.temporal_difference),
                                     ('R', self.reprojection)) if on)


# As in the paper: Bootstrapping I / II start from the spatiotemporal augmentation, and
# MONET is L_L + lambda_e L_E + lambda_p L_B with L_B on the spatiotemporal augmentation.
# bootstrap2_epipolar (ablation): Bootstrapping II's labels from the spatial augmentation
# + L_E (this package's earlier `monet`). epipolar (ablation): L_L + lambda_e L_E only, the
# measured row of L_E alone (its exact control: lambda_e = 0, the same batch plan).
# temporal_difference / reprojection (issue 22 item 4): the default spatiotemporal recipe +
# L_T or L_R on unlabeled instants (their exact controls: lambda_t / lambda_r = 0).
MODE_SPECS = {
    'supervised': ModeSpec(False, False, 0, False),
    'spatial': ModeSpec(True, False, 0, False),
    'spatiotemporal': ModeSpec(True, True, 0, False),
    'bootstrap1': ModeSpec(True, True, 1, False),
    'bootstrap2': ModeSpec(True, True, 2, False),
    'monet': ModeSpec(True, True, 0, True),
    'bootstrap2_epipolar': ModeSpec(True, False, 2, True),
    'epipolar': ModeSpec(False, False, 0, True),
    'temporal_difference': ModeSpec(True, True, 0, False, temporal_difference=True),
    'reprojection': ModeSpec(True, True, 0, False, reprojection=True),
    # issue 36: the default recipe + the anchored L_E on the same unlabeled instants as L_R
    # (its exact control: lambda_e = 0, the plan of `reprojection`)
    'reprojection_epipolar': ModeSpec(True, True, 0, True, reprojection=True),
}
# the modes with a loss on unlabeled instants (L_E, L_T or L_R), those epipolar_warmup delays
UNLABELED_MODES = tuple(m for m, spec in MODE_SPECS.items() if spec.unlabeled)


@dataclass(frozen=True)
class TrainConfig:
    # reprojection (L_L + L_B on the gated spatiotemporal tracks + L_R): the lowest 2D and 3D
    # error measured at the default recipe, on the synthetic rig (every seed, -29% 3D against
    # supervised) and on the real Pose2Sim recording (every label set, -8% 3D mean)
    # (bench/results/accuracy.md, real.md, issue 22); supervised is the row it is compared with
    mode: str = setting('reprojection', "training mode (a row of the paper's Table 1, or an "
                        "addition: reprojection, L_L + L_B on the labels' verified "
                        "optical-flow tracks + L_R towards the views' triangulated consensus "
                        'on unlabeled instants, has the lowest error measured at the defaults; '
                        'reprojection_epipolar adds the anchored epipolar term L_E, a little '
                        'better than its exact control on the synthetic rig; the symmetric '
                        'L_E of the paper is not trained any more)',
                        choices=MODES)
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
    batch_unlabeled: int = setting(2, 'unlabeled instants (with several labelled subjects: '
                                   '(instant, subject) rows) per step (L_E, L_T, L_R)', minimum=0,
                                   maximum=MAX_BATCH)
    views_per_instant: int = setting(0, 'views of each unlabeled instant (L_E: all their '
                                     'pairs; L_R: their consensus); 0 = every view of the rig',
                                     minimum=0, maximum=64)
    lambda_e: float = setting(5.0, 'weight of the epipolar term L_E (anchored: each view '
                              'pulled onto the epipolar lines of the confident views that '
                              'agree with each other, never the other way)', minimum=0.0)
    epipolar_kernel_px: float = setting(1.0, 'L_E: scale of its Cauchy kernel (heatmap px): a '
                                        'view farther off its lines is pulled more gently',
                                        minimum=0.0, exclusive_minimum=True, maximum=1e3)
    epipolar_agreement_px: float = setting(
        2.0, 'L_E: two confident views agree (and may anchor others) when their peaks lie '
        "within this many heatmap px of each other's epipolar lines", minimum=0.0,
        exclusive_minimum=True, maximum=1e3)
    epipolar_fit_heat_px: float = setting(
        1.0, 'L_E starts (after the warm-up) at the first step where the median distance of '
        "the detector's peaks to the labels of its labelled crops is at most this many "
        "heatmap px: its anchors are the detector's own peaks", minimum=0.0,
        exclusive_minimum=True, maximum=1e3)
    lambda_p: float = setting(1.0, 'weight of the pseudo-label loss L_B', minimum=0.0)
    lambda_t: float = setting(1.0, 'temporal_difference: weight of the temporal-difference '
                              'loss L_T (frame-to-frame jumps of the soft-argmax beyond '
                              'temporal_epsilon)', minimum=0.0)
    temporal_epsilon: float = setting(1.0, 'temporal_difference: frame-to-frame motion '
                                      '(heatmap px) L_T allows for free', minimum=0.0)
    lambda_r: float = setting(1.0, 'reprojection: weight of the reprojection-consistency loss '
                              "L_R (each view's heatmap towards the reprojection of the "
                              "views' RANSAC triangulation)", minimum=0.0)
    epipolar_warmup: float = setting(0.3, f'{", ".join(UNLABELED_MODES)}: fraction of the '
                                     'steps trained without the loss on unlabeled instants '
                                     '(L_E, L_T or L_R) before it starts',
                                     minimum=0.0, maximum=0.95)
    lr: float = setting(1e-3, 'Adam learning rate (peak, after the warm-up)', minimum=0.0,
                        exclusive_minimum=True)
    lr_schedule: str = setting('step', 'learning-rate schedule after the warm-up: step (x '
                               'lr_decay every lr_decay_every steps), cosine (down to lr_final '
                               'x lr at `steps`) or constant',
                               choices=('step', 'cosine', 'constant'))
    lr_warmup_steps: int = setting(0, 'steps of linear learning-rate warm-up from lr / '
                                   '(lr_warmup_steps + 1) to lr', minimum=0)
    lr_final: float = setting(0.02, 'cosine schedule: learning rate at the last step, as a '
                              'fraction of lr', minimum=0.0, maximum=1.0)
    lr_decay: float = setting(0.9, 'step schedule: learning-rate factor every lr_decay_every '
                              'steps', minimum=0.0, maximum=1.0, exclusive_minimum=True)
    lr_decay_every: int = setting(500, 'step schedule: steps between learning-rate decays',
                                  minimum=1)
    sigma: float = setting(2.0, 'Gaussian target sigma (heatmap px)', minimum=0.0,
                           exclusive_minimum=True)
    checkpoint_every: int = setting(500, 'steps between checkpoints', minimum=1)
    seed: int = setting(0, 'random seed (sampling, augmentation, initialisation)', minimum=0)
    device: str = setting('auto', 'torch device: auto (CUDA when present), cpu, cuda, cuda:N')
    precision: str = setting('float32', 'training arithmetic: float32, bfloat16 (the '
                             'network forward under torch.autocast; losses, weights and '
                             'checkpoints stay float32; only where the CPU (AVX512-BF16 / AMX) '
                             'or GPU runs bfloat16 natively), or auto (bfloat16 where native, '
                             'else float32; the default of monet train and the learner)',
                             choices=PRECISIONS)
    eval_fraction: float = setting(0.0, 'held-out tail of the recording, never trained on '
                                   '(0 = train on everything, for real use; e.g. 0.2 to keep '
                                   'a tail to measure generalisation on)', minimum=0.0,
                                   maximum=0.9)
    validation_labels: float = setting(
        0.0, 'fraction of the labelled instants held out as validation labels, never trained '
        'on (no L_L, no pseudo-labels, no L_R or L_E on them; labelled instants of the '
        'eval_fraction tail count first, the rest evenly spread; at least one when > 0, '
        'always leaving one to train on): the held-out labelled error of Trainer.validate',
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
    bootstrap_confidence: float = setting(0.0, 'bootstrapping: minimum heatmap peak '
                                          '(absolute floor; see bootstrap_relative_confidence)',
                                          minimum=0.0)
    bootstrap_relative_confidence: float = setting(
        0.5, "bootstrapping: minimum heatmap peak as a fraction of the median peak of the "
        "detector's own labelled views (its scale on data it fits; for L_R the labelled views "
        'of the same step); the cut-off is the larger of this and bootstrap_confidence',
        minimum=0.0, maximum=1.0)
    bootstrap_threshold_px: float = setting(8.0, 'bootstrapping and L_R (reprojection mode): '
                                            'RANSAC inlier threshold (px)',
                                            minimum=0.0, exclusive_minimum=True)
    bootstrap_min_views: int = setting(3, 'bootstrapping and L_R: minimum inlier views',
                                       minimum=2)
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
    # 10: measured (bench/results/accuracy.md, issue 22): the ungated tracks' drift taught
    # a 3D bias (3D error +43% against supervised); the first 10 frames: -13%, 2D -35%
    pseudo_max_frames: int = setting(
        10, 'spatiotemporal: train L_B only on tracked pseudo-labels at most this many frames '
        'from their seed (tracks drift: their error grows with the distance); 0 = every '
        'tracked frame (up to track_horizon). Crop boxes still use the whole track',
        minimum=0)
    pseudo_agreement_px: float = setting(
        0.0, 'spatiotemporal, with pseudo_max_frames: beyond pseudo_max_frames, keep a tracked '
        'label where the track of another seed reaching the same view and keypoint agrees '
        'within this many px (two independent tracks verify each other); 0 = keep none '
        'beyond', minimum=0.0)
    fit_warning_heat_px: float = setting(
        1.0, 'warn when the median error of the final detector on its own labelled views is '
        'above this many heatmap pixels (the output grid: 1/64 of the crop side for the small '
        'net): it does not fit its labels (raise lr or steps)', minimum=0.0,
        exclusive_minimum=True)

    distill_rounds: int = setting(
        0, "distillation rounds after the steps (issue 36; Lightning Pose 3D's route): each "
        "runs the detector over the training recording as `monet process --filter optim` "
        'does (tracked crops, fusion, bones + smoothness + robust reprojection), reprojects '
        'the filtered 3D into every view as pseudo-labels (L_D, weighted and gated by the '
        "filter's reprojection error) and trains distill_steps more steps with them; 0 = "
        'none', minimum=0, maximum=MAX_DISTILL_ROUNDS)
    distill_steps: int = setting(0, 'steps of each distillation round (0 = steps / 2); the '
                                 'learning-rate schedule runs on', minimum=0)
    batch_distill: int = setting(8, 'distillation rounds: distilled view crops per step (on '
                                 'top of the other parts)', minimum=0, maximum=MAX_BATCH)
    lambda_d: float = setting(1.0, 'weight of the distillation loss L_D (0: its exact control, '
                              'the same rounds, teacher runs and crops)', minimum=0.0)
    distill_gate_px: float = setting(8.0, 'L_D: a filtered point is a pseudo-label only where '
                                     'its mean reprojection error over its inlier views is at '
                                     'most this (px)', minimum=0.0, exclusive_minimum=True)
    distill_min_views: int = setting(3, 'L_D: fewest inlier views of a filtered point used',
                                     minimum=1)
    distill_residual_px: float = setting(2.0, 'L_D: weight of a pseudo-label = 1 / (1 + '
                                         '(reprojection error / this)^2)', minimum=0.0,
                                         exclusive_minimum=True)

    def __post_init__(self):
        validate_config(self)
        if self.input_size and (self.input_size % 8 or self.input_size < 32):
            raise ConfigError('TrainConfig', 'input_size',
                              f'must be 0 or a multiple of 8 >= 32, got {self.input_size}')
        if self.views_per_instant == 1:
            raise ConfigError('TrainConfig', 'views_per_instant',
                              'must be 0 (all views) or >= 2 (L_E compares pairs, L_R '
                              'triangulates), got 1')
        if self.pseudo_agreement_px and not self.pseudo_max_frames:
            raise ConfigError('TrainConfig', 'pseudo_agreement_px',
                              'applies beyond pseudo_max_frames: set pseudo_max_frames > 0 too')
        if self.distill_rounds and not self.batch_distill:
            raise ConfigError('TrainConfig', 'batch_distill',
                              f'0 with distill_rounds {self.distill_rounds}: no distilled crop '
                              "would be trained on (nothing would use the teacher's labels); "
                              'give batch_distill >= 1, or distill_rounds 0')
        if self.width and self.width < 4:
            raise ConfigError('TrainConfig', 'width', f'must be 0 or >= 4, got {self.width}')
        if self.device not in ('auto', 'cpu', 'cuda') and not (
                self.device.startswith('cuda:') and self.device[5:].isdigit()):
            raise ConfigError('TrainConfig', 'device',
                              f'expected auto, cpu, cuda or cuda:N, got {self.device!r}')

    def lr_factor(self, step):
        """Learning-rate multiplier of optimisation step `step` (0-based): linear warm-up over
        lr_warmup_steps, then the lr_schedule (cosine from 1 at the end of the warm-up to
        lr_final at `steps`, step decay, or constant)."""
        warm = self.lr_warmup_steps
        if step < warm:
            return (step + 1) / (warm + 1)
        if self.lr_schedule == 'constant':
            return 1.0
        if self.lr_schedule == 'step':
            return self.lr_decay ** ((step - warm) // self.lr_decay_every)
        progress = min(1.0, (step - warm) / max(1, self.steps - 1 - warm))
        return self.lr_final + (1.0 - self.lr_final) * 0.5 * (1.0 + math.cos(math.pi * progress))

    @property
    def distill_round_steps(self):
        """Steps of each distillation round (distill_steps, 0 = steps / 2, at least 1)."""
        return self.distill_steps or max(1, self.steps // 2)

    @property
    def total_steps(self):
        """steps + distill_rounds x distill_round_steps: where a run with its rounds ends."""
        return self.steps + self.distill_rounds * self.distill_round_steps

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
