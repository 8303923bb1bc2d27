"""Online learning: fine-tune a detector from recorded bags while the pipeline runs (no ROS).

    learner = OnlineLearner(LearnerConfig(bags=('rec/',), model='start.pt', out='run/'))
    while True:
        terms = learner.step()    # one Trainer step of `mode`; default L_L + L_B + L_R
        result = learner.checkpoint_due()   # every checkpoint_every steps: CheckpointResult
        if result is not None and result.published:
            announce(result.announcement())     # JSON of /monet/model

The bags are decoded once into memory (learning.recording) and replayed as a shuffled,
looping stream of multiview instants: every step the Trainer samples labelled views (L_L),
pseudo-labelled views (L_B) and unlabeled instants (L_R in the default mode `reprojection`;
L_E or L_T in the modes that train them) at random, forever. The held-out slice (the tail
of the recordings, `eval_fraction`) is never trained on, and neither are the validation
labels (`validation_labels`: a fraction of the labelled instants, the tail's first, the
rest evenly spread; trainer.TrainingData keeps them out of L_L, L_B and the unlabeled
instants' terms).
Every checkpoint is validated (Trainer.validate) without ground truth: the mean
epipolar divergence and reprojection error of the all-view triangulation of the detections
on the tail (agreement between views), and the error of the detections against the held-out
labels (`labelled_median_px`, `labelled_mean_px`: accuracy, in original image px).

Publication criterion (`publish_metric`, resolved once by publish_metric_key): a checkpoint
is announced only when its criterion is finite and not worse than that of the last
announced model (initially: the starting model, validated at start) by more than
`publish_tolerance_px`. The criterion is the mean held-out labelled error
(`labelled_mean_px`; publish_metric labelled, or auto when validation labels exist) or the
held-out reprojection error (`reprojection_px`; reprojection, or auto with a loud warning
when no labelled instant can be held out). Lower reprojection error alone is agreement, not
accuracy: a detector can make the views agree on the wrong points (bench/learner.py). The
last announcement is kept in out/published.json, so a restarted learner resumes with the
same reference (an announcement written before `labelled_mean_px` existed is re-validated).
A starting model must not have been trained on the validation labels: train it with the
same --validation-labels and --eval-fraction (the learner warns when the model's metadata
says otherwise).
"""
from dataclasses import dataclass, fields
import json
import math
from pathlib import Path
import time

import numpy as np

from monet_ros import json_text
from monet_ros.atomic import atomic_write, sha256_file
from monet_ros.config import MAX_THREADS, ConfigError, setting
from monet_ros.json_text import finite_or_none
from monet_ros.learning.config import LOSS_TERMS, MODES, TrainConfig
from monet_ros.models.detector import PRECISIONS

PUBLISHED = 'published.json'
# publish_metric -> the Trainer.validate key it compares (lower is better, px)
PUBLISH_METRICS = {'labelled': 'labelled_mean_px', 'reprojection': 'reprojection_px'}
FOREVER = 100_000_000     # TrainConfig.steps of a learner that runs until stopped


@dataclass(frozen=True)
class LearnerConfig(TrainConfig):
    """TrainConfig + where the data comes from and when models are announced."""
    # L_B on the labels' spatiotemporal tracks + L_R (each view towards the views'
    # triangulated consensus) on the unlabelled video: the mode with the lowest 2D and 3D
    # error measured (monet's L_E is 9x worse; issue 22); announcements are guarded by the
    # held-out labelled error (publish_metric)
    mode: str = setting('reprojection', "training mode (a row of the paper's Table 1, or "
                        'reprojection: + L_R, the lowest error measured)', choices=MODES)
    precision: str = setting('auto', 'training arithmetic: auto (bfloat16 where the CPU '
                             '(AVX512-BF16 / AMX) or GPU runs it natively, else float32), '
                             'float32 or bfloat16 (the network forward under torch.autocast; '
                             'weights and checkpoints stay float32)', choices=PRECISIONS)
    bags: tuple[str, ...] = setting((), 'recordings to learn from: rosbag2 folders, .mcap files '
                                    'or `monet synth` output folders', min_length=1)
    out: str = setting('', 'output folder: checkpoints/, model.pt, trainer_state.pt, '
                       'train_log.csv, published.json')
    model: str = setting('', "initial checkpoint ('' = a new network of `architecture`); "
                         'its architecture and keypoints define the network')
    rig: str = setting('', "rig file for all bags ('' = each folder's rig.yaml, else the "
                       "bag's CameraInfo + /tf_static)")
    rig_units: str = setting('', "length unit of a rig file that states none (m, cm, mm; "
                             "'' = the file's, else the rule of geometry.units)",
                             choices=('', 'm', 'cm', 'mm'))
    labels: str = setting('', "labels CSV (stamp_ns,camera,keypoint,u,v) for all bags "
                          "('' = each folder's labels.csv, else none)")
    skeleton: str = setting('human14', 'keypoint names (preset or YAML) when no initial model '
                            'is given')
    max_instants: int = setting(0, 'read at most this many instants per bag (0 = all)',
                                minimum=0)
    resume: bool = setting(True, 'continue from out/trainer_state.pt when it exists')
    publish_metric: str = setting(
        'auto', 'criterion of an announcement: labelled (mean error of the detections on the '
        'held-out validation labels, px: accuracy), reprojection (held-out reprojection '
        'error, px: agreement between views only) or auto (labelled when validation_labels '
        'holds out a labelled instant, else reprojection with a warning)',
        choices=('auto', 'labelled', 'reprojection'))
    validation_labels: float = setting(
        0.2, 'fraction of the labelled instants held out as validation labels (never trained '
        'on; the eval_fraction tail first, the rest evenly spread; at least one, leaving one '
        'to train on; 0 = none): the labelled publish_metric', minimum=0.0, maximum=0.9)
    publish_tolerance_px: float = setting(0.0, "announce a checkpoint when its publish_metric "
                                          "is at most the last announced one's + this (px)",
                                          minimum=0.0)
    validate_instants: int = setting(16, 'held-out instants used to validate a checkpoint',
                                     minimum=1)
    keep_checkpoints: int = setting(5, 'unannounced checkpoints kept besides the announced one '
                                    '(older ones are deleted; 0 = keep all)', minimum=0)
    threads: int = setting(0, 'torch CPU threads (0 = torch default)', minimum=0,
                           maximum=MAX_THREADS)
    # Redefined with the learner's meaning and defaults:
    steps: int = setting(0, 'training steps; after them training stops and the node stays up, '
                         'idle: its last announced model stays on /monet/model, its services '
                         'answer; stop it with Ctrl-C (0 = train until stopped)', minimum=0)
    checkpoint_every: int = setting(200, 'steps between checkpoints (each is validated and '
                                    'maybe announced)', minimum=1)
    epipolar_warmup: float = setting(0.0, 'fraction of `steps` trained without the loss on '
                                     'unlabeled instants (L_E, L_T, L_R; needs steps > 0; 0 '
                                     'when starting from a trained model)',
                                     minimum=0.0, maximum=0.95)
    eval_fraction: float = setting(0.2, 'held-out tail of the recording (not trained on; '
                                   'checkpoints are validated on it)', minimum=0.0,
                                   maximum=0.9)
    lr: float = setting(1e-4, 'Adam learning rate (fine-tuning a running detector)',
                        minimum=0.0, exclusive_minimum=True)

    def __post_init__(self):
        super().__post_init__()
        if not self.out:
            raise ConfigError('LearnerConfig', 'out', 'is required (an output folder)')
        if self.publish_metric == 'labelled' and not self.validation_labels:
            raise ConfigError('LearnerConfig', 'publish_metric', 'labelled needs '
                              'validation_labels > 0 (held-out labelled instants)')
        if self.distill_rounds:
            raise ConfigError('LearnerConfig', 'distill_rounds', 'the online learner trains '
                              'without rounds (it never stops to run the recording through '
                              'the detector); distil offline with monet train --distill-rounds')
        if self.epipolar_warmup and not self.steps:
            raise ConfigError('LearnerConfig', 'epipolar_warmup', 'needs steps > 0 (a '
                              'fraction of the steps); use 0 for a learner that runs until '
                              'stopped')

    def train_config(self):
        """The TrainConfig of the trainer (steps = FOREVER when 0)."""
        names = {f.name for f in fields(TrainConfig)}
        values = {k: v for k, v in self.to_dict().items() if k in names}
        values['steps'] = self.steps or FOREVER
        return TrainConfig(**values)


def publish_metric_key(publish_metric, validation_instants, warn=None, fraction=0.0):
    """The metrics key the criterion compares: PUBLISH_METRICS[publish_metric]; 'auto' ->
    labelled when `validation_instants` (the number of held-out labelled instants) > 0,
    else reprojection, said through warn(message) (one line; why none was held out:
    trainer.no_validation_text of `fraction`, the validation_labels setting). Raises
    ConfigError naming publish_metric / validation_labels when labelled is asked for and
    there is none."""
    if publish_metric not in ('auto', *PUBLISH_METRICS):
        raise ConfigError('LearnerConfig', 'publish_metric',
                          f'expected auto, labelled or reprojection, got {publish_metric!r}')
    if publish_metric == 'auto':
        if validation_instants:
            return PUBLISH_METRICS['labelled']
        if warn is not None:
            from monet_ros.learning.trainer import no_validation_text
            warn(f'publish_metric auto: {no_validation_text(fraction)}: announcing on the '
                 'held-out reprojection error, agreement between views, not accuracy')
        return PUBLISH_METRICS['reprojection']
    if publish_metric == 'labelled' and not validation_instants:
        raise ConfigError('LearnerConfig', 'validation_labels', 'holds out no labelled '
                          'instant (one is always left to train on: label at least two '
                          'instants), but publish_metric is labelled')
    return PUBLISH_METRICS[publish_metric]


def should_publish(metrics, reference_px, tolerance_px=0.0, metric='reprojection_px'):
    """(publish, reason): publish when metrics[metric] (a PUBLISH_METRICS value, px, lower
    is better) is finite and at most reference_px + tolerance_px (reference None or inf =
    nothing announced yet)."""
    name = {'labelled_mean_px': 'held-out labelled error',
            'reprojection_px': 'reprojection'}.get(metric, metric)
    err = metrics.get(metric, math.nan) if metrics else math.nan
    if err is None or not math.isfinite(err):
        what = '(nothing triangulated)' if metric == 'reprojection_px' else '(no detection)'
        return False, f'no finite {name} {what}'
    if reference_px is None or not math.isfinite(reference_px):
        return True, f'{name} {err:.3f} px (no reference yet)'
    if err <= reference_px + tolerance_px:
        return True, f'{name} {err:.3f} px <= {reference_px:.3f} px + {tolerance_px:g}'
    return False, f'{name} {err:.3f} px worse than the announced {reference_px:.3f} px'


@dataclass(frozen=True)
class CheckpointResult:
    """One validated checkpoint: path, step, sha256, held-out metrics (+ loss terms) and
    whether it was announced (and why)."""
    path: str
    step: int
    sha256: str
    metrics: dict
    published: bool
    reason: str

    def announcement(self):
        """The /monet/model JSON text."""
        return json_text.dumps({'path': self.path, 'step': self.step, 'sha256': self.sha256,
                                'metrics': self.metrics}, default=lambda x: None)


def _write_json_atomic(path, payload):
    with atomic_write(path, 'w') as stream:
        stream.write(json_text.dumps(payload, indent=1))


def concatenate_recordings(recordings):
    """One Recording of several with the same cameras (by name) and keypoints (the other
    subjects' labels kept, their instants renumbered)."""
    from monet_ros.learning.recording import Recording, RecordingError
    first = recordings[0]
    if len(recordings) == 1:
        return first
    names = [c.name for c in first.cameras]
    for rec in recordings[1:]:
        if [c.name for c in rec.cameras] != names:
            raise RecordingError(f'{rec.name}: cameras {[c.name for c in rec.cameras]} differ '
                                 f'from {first.name}: {names}')
    gt = None
    if all(r.gt3d is not None for r in recordings):
        gt = np.concatenate([r.gt3d for r in recordings])
    return Recording('+'.join(r.name for r in recordings), first.cameras,
                     np.concatenate([r.stamps for r in recordings]),
                     [np.concatenate([r.frames[v] for r in recordings])
                      for v in range(len(names))],
                     first.keypoints, np.concatenate([r.labels for r in recordings]), gt,
                     np.concatenate([r.other_labels for r in recordings]),
                     np.concatenate([r.other_instants + start for r, start in zip(
                         recordings, np.cumsum([0] + [len(r.stamps) for r in recordings]))]),
                     np.concatenate([r.other_subjects for r in recordings]))


def load_bags(config, keypoints):
    """The concatenated Recording of config.bags (keypoints: names, heatmap channel order)."""
    from monet_ros.learning.recording import load_recording
    return concatenate_recordings([
        load_recording(bag, rig=config.rig or None, rig_units=config.rig_units or None,
                       labels=config.labels or None,
                       skeleton=list(keypoints), max_instants=config.max_instants or None,
                       shared_labels=bool(config.labels) and len(config.bags) > 1)
        for bag in config.bags])


class OnlineLearner:
    """A Trainer over the bags plus validation, announcement bookkeeping and pruning.

    Not thread-safe: call from one thread (the node serialises with a lock)."""

    def __init__(self, config, log=print):
        import torch

        from monet_ros.learning.trainer import (
            Trainer,
            TrainingData,
            check_training_precision,
            pick_device,
        )
        from monet_ros.models import build_model, load_checkpoint
        from monet_ros.skeleton import load_skeleton

        if not isinstance(config, LearnerConfig):
            raise TypeError('config must be a LearnerConfig')
        self.config = config
        self.log = log
        if config.threads:
            torch.set_num_threads(config.threads)
        check_training_precision(config.precision, pick_device(config.device))
        self.out = Path(config.out)
        self.out.mkdir(parents=True, exist_ok=True)
        for stale in self.out.rglob('.*.tmp'):          # temporaries of a killed write
            stale.unlink()
        train_config = config.train_config()
        resume = config.resume and (self.out / 'trainer_state.pt').is_file()
        model = None
        if resume:           # the network of the last run (its weights come from the state)
            model, meta = load_checkpoint(self.out / 'model.pt')
            keypoints = meta['keypoints']
        elif config.model:
            model, meta = load_checkpoint(config.model)
            keypoints = meta['keypoints']
        else:
            keypoints = list(load_skeleton(config.skeleton).keypoints)
        probe = model or build_model(config.architecture, len(keypoints),
                                     **config.model_options())
        self.recording = load_bags(config, keypoints)
        data = TrainingData(self.recording, train_config, probe.input_size, probe.heatmap_size)
        if len(data.held_out) == 0:
            raise ConfigError('LearnerConfig', 'eval_fraction', 'leaves no held-out instant '
                              'to validate checkpoints on')
        if resume:
            self.trainer = Trainer.resume(self.out, data, config=train_config, model=model)
            log(f'resumed at step {self.trainer.step_count} from {self.out}')
        else:
            self.trainer = Trainer(train_config, data, self.out, model=model)
        log(f'training {self.trainer.precision_note}')
        self.data = data
        self.metric = publish_metric_key(config.publish_metric, len(data.validation_instants),
                                         self.trainer.warn, config.validation_labels)
        if not resume and config.model:
            self._check_start_model(meta)
        if not resume:             # a fresh run: an older run's announcement is no reference
            (self.out / PUBLISHED).unlink(missing_ok=True)
        self.published = self._load_published()
        if self.published is not None:
            self.reference_px = self.published.metrics.get(self.metric)
            if self.reference_px is None:      # written before this metric existed
                self.reference_px = self.validate_checkpoint(self.published.path).get(
                    self.metric)
            log(f'last announced model: {self.published.path} (step {self.published.step}, '
                f'{self.metric} {self.reference_px})')
        else:
            start = self.trainer.validate(max_instants=config.validate_instants)
            self.start_metrics = start
            self.reference_px = start.get(self.metric)
            log(f'starting model: held-out reprojection {start.get("reprojection_px")} px, '
                f'held-out labelled error {start.get("labelled_mean_px")} px (mean; median '
                f'{start.get("labelled_median_px")}), epipolar divergence '
                f'{start.get("epipolar_divergence")}; announcing on {self.metric}')
        if self.reference_px is None:
            self.reference_px = math.inf
        self.checkpoints = 0
        self.last_result = None
        self.step_times = []
        log(f'{self.recording.name}: {self.recording.num_instants} instants x '
            f'{self.recording.num_views} views, {len(data.labelled_instants)} labelled, '
            f'{len(data.unlabeled_instants)} unlabeled, {len(data.held_out)} held out, '
            f'{len(data.validation_instants)} labelled instants held out for validation; '
            f'mode {config.mode}, device {self.trainer.device}')

    def _check_start_model(self, meta):
        """Warn when the starting model's metadata says it was trained on this recording with
        another validation split (it may have seen the validation labels: its held-out
        labelled error, the first reference, is then optimistic)."""
        if self.metric != PUBLISH_METRICS['labelled']:
            return
        trained = meta.get('train_config') or {}
        if meta.get('recording') != self.recording.name or not trained:
            return
        split = ('validation_labels', 'eval_fraction')
        mine = self.trainer.config
        if any(trained.get(k, 0.0 if k == 'validation_labels' else None) != getattr(mine, k)
               for k in split):
            self.trainer.warn(
                f'the starting model {self.config.model} was trained on {self.recording.name} '
                f'with ' + ', '.join(f'{k}={trained.get(k)}' for k in split) + ', not '
                + ', '.join(f'{k}={getattr(mine, k)}' for k in split) + ': it may have been '
                'trained on the validation labels (its held-out labelled error is optimistic); '
                'train it with the same settings')

    def validate_checkpoint(self, path):
        """Trainer.validate of the weights in the checkpoint at `path` (the trainer's own
        weights are untouched)."""
        from monet_ros.models import load_checkpoint
        model, _ = load_checkpoint(path)
        current = self.trainer.model
        self.trainer.model = model.to(self.trainer.device)
        try:
            return finite_or_none(self.trainer.validate(
                max_instants=self.config.validate_instants))
        finally:
            self.trainer.model = current

    def _load_published(self):
        path = self.out / PUBLISHED
        if not path.is_file():
            return None
        try:
            info = json.loads(path.read_text())
            result = CheckpointResult(info['path'], int(info['step']), info['sha256'],
                                      info['metrics'], True, 'announced before')
        except (ValueError, KeyError, TypeError) as error:
            self.log(f'{path}: ignored ({error})')
            return None
        if not Path(result.path).is_file() or sha256_file(result.path) != result.sha256:
            self.log(f'{path}: the announced checkpoint {result.path} is gone or changed; '
                     'ignored')
            return None
        return result

    @property
    def step_count(self):
        return self.trainer.step_count

    @property
    def finished(self):
        return bool(self.config.steps) and self.trainer.step_count >= self.config.steps

    def step(self):
        """One training step; returns the loss terms ({'loss', 'lr', 'step'} and those of
        learning.config.LOSS_TERMS the mode has)."""
        start = time.perf_counter()
        terms = self.trainer.step()
        self.step_times = (self.step_times + [time.perf_counter() - start])[-50:]
        return terms

    @property
    def steps_per_s(self):
        return len(self.step_times) / sum(self.step_times) if self.step_times else 0.0

    def checkpoint_due(self):
        """After step(): the CheckpointResult when the trainer just wrote a scheduled
        checkpoint (every checkpoint_every steps), else None."""
        c = self.trainer.config
        n = self.trainer.step_count
        if n and (n % c.checkpoint_every == 0 or n == c.steps):
            return self.evaluate(self.trainer.last_checkpoint)
        return None

    def save(self):
        """Write a checkpoint now (e.g. on request) and evaluate it."""
        if self.trainer.last_checkpoint is not None and \
                self.trainer.last_checkpoint.name == f'step_{self.step_count:06d}.pt' and \
                self.last_result is not None and self.last_result.step == self.step_count:
            return self.last_result                       # nothing trained since
        return self.evaluate(self.trainer.save())

    def evaluate(self, path):
        """Validate the checkpoint at `path` (the trainer's current weights) on the held-out
        slice and the validation labels, decide whether to announce it (should_publish on
        self.metric against reference_px, the last announced value), prune old
        checkpoints."""
        metrics = self.trainer.validate(max_instants=self.config.validate_instants)
        metrics.update({f'loss_{k}': v for k, v in self.trainer.last_terms.items()
                        if k == 'loss' or k in LOSS_TERMS})
        metrics = finite_or_none(metrics)
        publish, reason = should_publish(metrics, self.reference_px,
                                         self.config.publish_tolerance_px, self.metric)
        result = CheckpointResult(str(Path(path).resolve()), self.step_count,
                                  sha256_file(path), metrics, publish, reason)
        self.checkpoints += 1
        self.last_result = result
        if publish:
            self.prepare_onnx(result.path)
            self.published = result
            self.reference_px = metrics[self.metric]
            _write_json_atomic(self.out / PUBLISHED, {
                'path': result.path, 'step': result.step, 'sha256': result.sha256,
                'metrics': result.metrics, 'publish_metric': self.metric})
        self.prune()
        return result

    def prepare_onnx(self, path):
        """Export a checkpoint to be announced for the detectors' ONNX Runtime backend
        (their default on a CPU: models.detector.resolve_backend) beside it, as the detector
        itself caches it (Detector.from_checkpoint with backend onnxruntime, keyed by the
        checkpoint's sha256): the export (~1 s for the small net) is then done here, not in
        a running detector's reload. Skipped without onnxruntime; a failed export is said
        and left to the detectors."""
        from importlib.util import find_spec

        from monet_ros.models import Detector
        from monet_ros.models.onnx_backend import OnnxBackendError
        if not find_spec('onnxruntime'):
            return
        try:
            Detector.from_checkpoint(path, device='cpu', backend='onnxruntime',
                                     precision='float32')
        except (OnnxBackendError, ValueError, OSError) as error:
            self.log(f'{path}: ONNX export for the detectors failed, they will export it '
                     f'themselves: {error}')

    def prune(self):
        """Delete unannounced checkpoints beyond the newest keep_checkpoints (with their
        ONNX exports)."""
        keep = self.config.keep_checkpoints
        if not keep:
            return
        announced = Path(self.published.path).name if self.published else None
        files = sorted((self.out / 'checkpoints').glob('step_*.pt'))
        candidates = [p for p in files if p.name != announced]
        for path in candidates[:-keep]:
            path.unlink(missing_ok=True)
            for export in path.parent.glob(f'{path.stem}.*.onnx'):
                export.unlink(missing_ok=True)
