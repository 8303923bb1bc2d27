"""Label efficiency on real video: the 4-camera Pose2Sim recording, a few labelled instants.

The recording is ../shared/data/derived_pose2sim_4cam_mcap (100 instants, 4 cameras, JPEG at
half resolution; cameras from its own CameraInfo + /tf_static). The reference is Pose2Sim's
.trc of the same trial (pose2sim_demo_balancing, itself a triangulation of OpenPose: it
reprojects 4-10 px from OpenPose's 2D at half resolution, the floor of every figure here),
trc (X, Y, Z) = world (Y, Z, X), its 14 human14 joints (head = Pose2Sim's Head marker).

For each count N in --labels (2, 3, 5, 10) the labelled instants are N instants spread over
the recording (one drawn with each of --seeds in each of N equal strata: one label set per
seed, also the training seed); their labels are the reference projected into all 4 views
(project_to_views: none outside an image). Each mode (default supervised, spatiotemporal,
monet; any `monet train --mode`) then trains the same network from the same initialisation
with the same wall-time budget (--budget-s per run: the step count of each mode is set from
a short timing probe of its step cost; the table gives the wall times actually spent), with
the default TrainConfig recipe (no held-out tail: every instant is in the training split,
and the scores below are on the instants without labels, which L_E and bootstrapping see
unlabelled). Each model is saved as a checkpoint and scored through the code a user runs:
`monet process`'s core (commands.process.process_recording on the recording's bag: the live
detector's tracked crop rule, crop_rule.TrackedCrops, and fusion.fuse_heatmaps), and,
beside it, for detection quality, on ground-truth crops (boxes of the reference projected
into each view, square, 25% margin; detections fused by fusion.fuse_points). Both are
scored on the unlabelled instants against the reference:

  3D error (mm): median / mean / p90 over the triangulated joints; `tri` = share triangulated;
  PCK@5/10/20 px: share of the detections (every view, every joint the reference projects
    into) within 5/10/20 px (half-resolution image pixels) of the reference's projection.

Rows without training: OpenPose (pretrained BODY_25B, Pose2Sim's pose-associated 2D) fused by
`fuse_points` with Pose2Sim's rule (likelihood >= 0.3, exclusion at 15 px full resolution =
7.5 px here): this is the reference's own input, so its 3D error is ~0 by construction and its
2D PCK is the floor of the reference; image-blind baselines: the pose of the nearest labelled
instant, and the mean labelled pose (projected for 2D).

--modes takes `monet train` modes, each optionally with its own TrainConfig overrides after a
colon: `reprojection:lambda_r=0` is the default mode's exact control (the same run and batch
plan with the term's weight 0), labelled `reprojection (lambda_r=0)` in the tables.

Every finished run is appended to OUT.runs.jsonl at once; a rerun with the same OUT skips the
runs already there (same labels, seed, model, steps or budget, overrides), so a long curve
can be stopped and resumed without losing a run. With several --seeds and --labels, OUT.md
also gets the learning curve: per count and model the mean over label sets, and the paired
differences against supervised and against each exact control (how many sets improved).

--peer PEER_JSON: the sleap-nn rows of bench/peer.py runs (same data, labels and scoring; run
it with the same --budget-s) join the table and the curves where labels and seed match.

Writes OUT.md (tables + the command), OUT.json and OUT.png (curves: 3D median error and
PCK@10 px against the number of labelled instants). --quick: 3 labelled instants, all modes,
45 s per run (a smoke run of the whole path, a few minutes; not the figures).
    .venv/bin/python bench/real.py --quick
    .venv/bin/python bench/real.py --budget-s 300 --jobs 2      # the figures, about 40 min
"""
import argparse
from concurrent.futures import ProcessPoolExecutor, as_completed
import json
import multiprocessing
import os
from pathlib import Path
import shutil
import sys
import time

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from monet_ros.commands.demo import default_data_root  # noqa: E402
from monet_ros.learning.config import MODES as TRAIN_MODES  # noqa: E402
from monet_ros.learning.config import TrainConfig  # noqa: E402

BAG = Path('derived_pose2sim_4cam_mcap/pose2sim_balancing_4cam')
TRIAL = Path('pose2sim_demo_balancing/S00_P00_SingleParticipant/S00_P00_T01_BalancingTrial')
# human14 joint -> Pose2Sim marker (BODY_25B keypoint) of the .trc
MARKERS = {'head': 'Head', 'neck': 'Neck', 'r_shoulder': 'RShoulder', 'r_elbow': 'RElbow',
           'r_wrist': 'RWrist', 'l_shoulder': 'LShoulder', 'l_elbow': 'LElbow',
           'l_wrist': 'LWrist', 'r_hip': 'RHip', 'r_knee': 'RKnee', 'r_ankle': 'RAnkle',
           'l_hip': 'LHip', 'l_knee': 'LKnee', 'l_ankle': 'LAnkle'}
MODES = ('supervised', 'spatiotemporal', 'monet')        # the default rows
PCK_PX = (5, 10, 20)
_STATE = {}             # recording and reference, loaded before forking workers
_PREPARED = {}          # (labels, seed, config of the crops) -> TrainingData, per process


def load_reference(root, keypoints):
    """(T, C, 3) world metres of the .trc, in the order of `keypoints`."""
    from monet_ros.geometry.pose2sim import read_trc, trc_to_world

    names, _, trc = read_trc(next((root / TRIAL / 'pose-3d').glob('*.trc')))
    index = [names.index(MARKERS[k]) for k in keypoints]
    return trc_to_world(trc[:, index])


def load_openpose(root, keypoints, num_views):
    """(T, V, C, 2) OpenPose 2D in half-resolution pixels and (T, V, C) likelihoods."""
    from monet_ros.geometry.pose2sim import BODY_25B_IDS, read_openpose_folder

    folders = sorted((root / TRIAL / 'pose-associated').glob('cam*_json'))
    if len(folders) != num_views:
        raise SystemExit(f'{len(folders)} OpenPose folders for {num_views} cameras')
    ids = [BODY_25B_IDS[MARKERS[k]] for k in keypoints]
    det = np.stack([read_openpose_folder(f)[:, ids] for f in folders], axis=1)
    uv = (det[..., :2] + 0.5) * 0.5 - 0.5        # full -> half resolution (the bag's K)
    return uv, np.nan_to_num(det[..., 2])


def choose_instants(num_instants, count, seed):
    """`count` instants, one drawn (seeded) in each of `count` equal strata of the recording."""
    rng = np.random.default_rng(seed)
    edges = np.linspace(0, num_instants, count + 1).round().astype(int)
    return np.array([rng.integers(a, b) for a, b in zip(edges[:-1], edges[1:])])


def project_reference(reference, cameras):
    """(T, C, 3) -> (T, V, C, 2) pixels (NaN outside an image or behind a camera)."""
    from monet_ros.learning.pseudo_labels import project_to_views

    T, C, _ = reference.shape
    return project_to_views(reference.reshape(-1, 3), cameras).reshape(
        len(cameras), T, C, 2).transpose(1, 0, 2, 3)


def fuse(points, confidence, cameras, config=None):
    """(T, V, C, 2) + (T, V, C) -> (T, C, 3) with fusion.fuse_frames (all instants at once)."""
    from monet_ros.fusion import FusionConfig, fuse_frames

    return fuse_frames(points, confidence, cameras, config or FusionConfig())['X']


def score(X, points, reference, reference2d, instants):
    """3D error (mm) and 2D PCK of predictions X (T, C, 3), points (T, V, C, 2) or None."""
    err = np.linalg.norm(X[instants] - reference[instants], axis=-1) * 1000.0
    have = np.isfinite(reference[instants, :, 0])
    ok = np.isfinite(err)
    e = err[ok]
    out = {'median_mm': float(np.median(e)) if e.size else None,
           'mean_mm': float(np.mean(e)) if e.size else None,
           'p90_mm': float(np.percentile(e, 90)) if e.size else None,
           'triangulated': float(ok.sum() / max(have.sum(), 1))}
    if points is not None:
        ref = reference2d[instants]
        inside = np.isfinite(ref[..., 0])
        d = np.linalg.norm(points[instants] - ref, axis=-1)[inside]
        d = np.where(np.isfinite(d), d, np.inf)                  # missing = a miss
        for px in PCK_PX:
            out[f'pck{px}'] = float((d <= px).mean())
    return out


def process_path(bag, checkpoint, out, stamps, cameras, **options):
    """`monet process` on `bag` with `checkpoint` (commands.process.process_recording, its
    defaults: tracked crops, fuse_heatmaps), results read back from its csv / npz exports.

    stamps (T,) ns: the recording's instants; cameras: the recording's cameras (their order).
    Returns X (T, C, 3) world m and points (T, V, C, 2) its detections in source pixels, NaN
    for instants or views it gave nothing for, and the number of its frames whose stamp is
    not an instant of the recording (0 expected). options: more process_recording
    arguments (precision, calibration)."""
    from monet_ros.commands.process import process_recording
    from monet_ros.io.export_tables import read_anipose_csv

    process_recording(bag, checkpoint, out, progress=False, exports=('csv', 'npz'), **options)
    table = read_anipose_csv(Path(out) / 'keypoints3d.csv')
    det = np.load(Path(out) / 'detections2d.npz')
    stamps = np.asarray(stamps, dtype=np.int64)
    index = {int(s): n for n, s in enumerate(stamps)}
    C = table['X'].shape[1]
    X = np.full((len(stamps), C, 3), np.nan)
    points = np.full((len(stamps), len(cameras), C, 2), np.nan)
    names = [str(c) for c in det['cameras']]
    unmatched = 0
    for row, stamp in enumerate(table['stamps_ns']):
        n = index.get(int(stamp))
        if n is None:
            unmatched += 1
            continue
        X[n] = table['X'][row]
    for row, stamp in enumerate(det['stamps_ns']):
        n = index.get(int(stamp))
        if n is None:
            continue
        for v, cam in enumerate(cameras):
            if cam.name in names:
                points[n, v] = det['points2d'][row, names.index(cam.name)]
    return X, points, unmatched


def ground_truth_crop_path(model, metadata, recording, reference2d, margin=0.25):
    """Detection quality on ground-truth crops: every view cropped on the reference's
    projection (square, `margin`), detections fused by fuse_points. Returns (X (T, C, 3),
    points (T, V, C, 2))."""
    from monet_ros.evaluation.evaluate import detect_instants
    from monet_ros.learning.dataset import boxes_from_points
    from monet_ros.models.detector import Detector

    detector = Detector(model, metadata)
    boxes = boxes_from_points(reference2d, aspect=1.0, margin=margin)
    det = detect_instants(detector, recording, np.arange(recording.num_instants), boxes,
                          crop='boxes')
    return fuse(det['points'], det['confidence'], recording.cameras), det['points']


def labelled_recording(recording, reference2d, instants):
    """The recording (frames shared, not copied) labelled at `instants` only."""
    import dataclasses

    labels = np.full_like(recording.labels, np.nan)
    labels[instants] = reference2d[instants]
    return dataclasses.replace(recording, labels=labels)


def probe_seconds_per_step(config, data, steps=6):
    """Seconds per step of this mode (its most expensive phase), from a short timing run."""
    import dataclasses

    from monet_ros.learning.trainer import Trainer

    options = {'steps': 10 ** 6}
    if config.mode == 'monet':
        options['epipolar_warmup'] = 0.0            # time the L_E phase ...
    trainer = Trainer(dataclasses.replace(config, **options), data, warn=lambda m: None)
    trainer.step()                                   # first step: allocations
    start = time.monotonic()
    for _ in range(steps):
        trainer.step()
    full = (time.monotonic() - start) / steps
    if config.mode != 'monet':
        return full
    trainer = Trainer(dataclasses.replace(config, steps=10 ** 6, epipolar_warmup=0.95), data,
                      warn=lambda m: None)            # ... and the warm-up phase
    trainer.step()
    start = time.monotonic()
    for _ in range(steps):
        trainer.step()
    warm = (time.monotonic() - start) / steps
    w = config.epipolar_warmup
    return w * warm + (1 - w) * full


def teacher_precision(process_dir, config, recording, reference, reference2d, instants):
    """What a distillation round taught, against the reference on `instants` (the unlabelled
    ones): its pseudo-labels made as the round makes them (learning.distill.distilled_labels
    on the teacher's `monet process --filter optim` keypoints3d.csv in `process_dir`, with
    `config`'s distill settings) -> dict: pl_* their 2D error (px: median, mean, p90, share
    within 2 / 5 px) to the reference's projection, pl_kept how many; teacher_mean_mm /
    teacher_p90_mm the filtered 3D's error, teacher_kept_mean_mm that of the points the
    gate keeps (>= distill_min_views inlier views, error <= distill_gate_px)."""
    from monet_ros.io.export_tables import read_anipose_csv
    from monet_ros.learning.distill import align_to_instants, distilled_labels

    table = read_anipose_csv(process_dir / 'keypoints3d.csv')
    stamps = recording.stamps
    X, matched = align_to_instants(stamps, table['stamps_ns'], table['X'])
    error = align_to_instants(stamps, table['stamps_ns'], table['error'])[0]
    ncams = align_to_instants(stamps, table['stamps_ns'], table['ncams'], fill=0)[0]
    cells = np.zeros(reference2d.shape[:3], bool)
    cells[instants] = True
    labels = distilled_labels(X, error, ncams, recording.cameras, cells,
                              gate_px=config.distill_gate_px,
                              min_views=config.distill_min_views,
                              residual_px=config.distill_residual_px, matched=matched)
    px = np.linalg.norm(labels.points - reference2d, axis=-1)[labels.weight > 0]
    px = px[np.isfinite(px)]
    mm = np.linalg.norm(X[instants] - reference[instants], axis=-1) * 1000.0
    with np.errstate(invalid='ignore'):
        kept = (ncams[instants] >= config.distill_min_views) & \
            (error[instants] <= config.distill_gate_px) & np.isfinite(mm)
    have = np.isfinite(mm)
    return {'pl_median_px': float(np.median(px)), 'pl_mean_px': float(px.mean()),
            'pl_p90_px': float(np.percentile(px, 90)), 'pl_within2': float((px <= 2).mean()),
            'pl_within5': float((px <= 5).mean()), 'pl_kept': int(px.size),
            'teacher_mean_mm': float(mm[have].mean()),
            'teacher_p90_mm': float(np.percentile(mm[have], 90)),
            'teacher_kept_mean_mm': float(mm[kept].mean())}


def run_job(job):
    """Worker: train one mode on one label set within the budget, detect, fuse, score."""
    import dataclasses
    import tempfile

    import torch

    from monet_ros.learning.trainer import Trainer, TrainingData
    from monet_ros.models import build_model, save_checkpoint

    torch.set_num_threads(1)
    count, arm, budget_s, fixed_steps, overrides, seed = job[:6]
    filter_method = job[6] if len(job) > 6 else 'none'
    mode, arm_overrides = parse_arm(arm)
    overrides = {**overrides, **arm_overrides}
    recording, reference, reference2d = _STATE['recording'], _STATE['reference'], \
        _STATE['reference2d']
    instants = choose_instants(recording.num_instants, count, seed)
    rec = labelled_recording(recording, reference2d, instants)
    config = TrainConfig(mode=mode, seed=seed, **overrides)
    probe = build_model(config.architecture, rec.num_keypoints, **config.model_options())
    key = (count, seed, probe.input_size, probe.heatmap_size, config.box_source,
           config.box_margin, config.cache_scale, config.eval_fraction)
    if key not in _PREPARED:                    # crops are the same for every mode
        _PREPARED.clear()
        _PREPARED[key] = TrainingData(rec, config, probe.input_size, probe.heatmap_size)
    data = _PREPARED[key]
    if fixed_steps:
        steps = fixed_steps
    else:
        per_step = probe_seconds_per_step(config, data)
        extra = 0.0
        if mode == 'bootstrap2' or (mode == 'monet' and config.monet_bootstrap_rounds):
            trainer = Trainer(config, data, warn=lambda m: None)
            start = time.monotonic()
            trainer.detect(data.unlabeled_instants)
            rounds = 2 if mode == 'bootstrap2' else config.monet_bootstrap_rounds
            extra = rounds * (time.monotonic() - start)
        steps = max(20, int((budget_s - extra) / per_step))
    config = dataclasses.replace(config, steps=steps, checkpoint_every=10 ** 6)
    said = []
    unlabelled = np.setdiff1d(np.arange(rec.num_instants), instants)
    start = time.monotonic()
    if config.distill_rounds:       # as `monet train --distill-rounds` runs them
        from monet_ros.commands.train_distill import train_with_distillation
        train_dir = tempfile.mkdtemp(prefix='monet-real-distill-')
        trainer = Trainer(config, data, Path(train_dir), warn=said.append)
        summary = train_with_distillation(
            trainer, _STATE['bag'], skeleton='human14', progress=False,
            say=lambda line: print(f'[{count} labels {mode}] {line}', file=sys.stderr,
                                   flush=True))
        for stats in summary.get('distill') or []:    # before the round's folder goes
            stats['precision'] = teacher_precision(Path(stats['process']), config, recording,
                                                   reference, reference2d, unlabelled)
        shutil.rmtree(train_dir, ignore_errors=True)
    else:
        trainer = Trainer(config, data, warn=said.append)
        summary = trainer.run(progress=False)
    train_s = time.monotonic() - start
    with tempfile.TemporaryDirectory(prefix='monet-real-') as tmp:
        checkpoint = Path(tmp) / 'model.pt'
        save_checkpoint(checkpoint, trainer.model, trainer.metadata())
        X, points, unmatched = process_path(_STATE['bag'], checkpoint, Path(tmp) / 'process',
                                            rec.stamps, rec.cameras)
        if filter_method != 'none':     # the same model through `monet process --filter M`
            from monet_ros.temporal import FilterConfig
            X_f, points_f, _ = process_path(
                _STATE['bag'], checkpoint, Path(tmp) / 'filtered', rec.stamps, rec.cameras,
                filter_config=FilterConfig(method=filter_method))
    result = score(X, points, reference, reference2d, unlabelled)
    if filter_method != 'none':
        filtered = score(X_f, points_f, reference, reference2d, unlabelled)
        result['filter'] = filter_method
        result.update({f'filter_{k}': filtered[k] for k in ('median_mm', 'mean_mm', 'p90_mm')})
    result['process_unmatched_frames'] = unmatched
    X_gt, points_gt = ground_truth_crop_path(trainer.model, trainer.metadata(), rec,
                                             reference2d)
    result['gt_crop'] = score(X_gt, points_gt, reference, reference2d, unlabelled)
    result.update({'labels': count, 'seed': seed, 'mode': arm_label(arm), 'steps': steps,
                   'train_s': round(train_s, 1),
                   'instants': instants.tolist(), 'fit_px': summary['fit']['median_px'],
                   'fit_heat': summary['fit']['median_heat'],
                   'pseudo_labels': summary['pseudo_labels'], 'warnings': said,
                   'bootstrap': summary['bootstrap'], 'distill': summary.get('distill')})
    print(f'[{count} labels {arm_label(arm)}, seed {seed}] {steps} steps in {train_s:.0f} s: '
          f'monet process 3D median {fmt(result["median_mm"], ".0f")} mm, PCK@10 '
          f'{result["pck10"]:.3f}; GT crops {fmt(result["gt_crop"]["median_mm"], ".0f")} mm, fit '
          f'{result["fit_px"]:.1f} px, {len(said)} warnings', file=sys.stderr, flush=True)
    return result


def parse_value(value):
    """A --set / --modes override value: YAML, with 1e-3 read as a float."""
    import yaml
    value = yaml.safe_load(value)
    if isinstance(value, str):                     # YAML 1.1 reads 1e-3 as a string
        try:
            value = float(value)
        except ValueError:
            pass
    return value


def parse_arm(arm):
    """(mode, overrides) of a --modes entry 'MODE' or 'MODE:KEY=VALUE[,KEY=VALUE]'.
    Raises ValueError naming the entry."""
    mode, _, rest = arm.partition(':')
    if mode not in TRAIN_MODES:
        raise ValueError(f'--modes {arm!r}: {mode!r} is not a monet train mode '
                         f'({", ".join(TRAIN_MODES)})')
    overrides = {}
    for pair in filter(None, rest.split(',')):
        key, sep, value = pair.partition('=')
        if not sep or key not in TrainConfig.__dataclass_fields__:
            raise ValueError(f'--modes {arm!r}: {pair!r} is not KEY=VALUE with KEY a '
                             'TrainConfig field')
        overrides[key] = parse_value(value)
    return mode, overrides


def arm_label(arm):
    """The table's name of a --modes entry: 'reprojection (lambda_r=0)'."""
    mode, _, rest = arm.partition(':')
    return f'{mode} ({rest.replace(",", ", ")})' if rest else mode


def paired_arms(arms):
    """(arm, reference) label pairs of the curve's paired differences: every arm that is not
    an exact control against supervised, and every exact control against its arm. An exact
    control sets one or more weights to 0 (`reprojection:lambda_r=0`,
    `reprojection_epipolar:lambda_e=0`, `reprojection:distill_rounds=1,lambda_d=0`); its
    arm is the one of the same mode whose overrides are the control's without those zeros,
    none of them 0 (`reprojection`, `reprojection_epipolar:lambda_e=5`,
    `reprojection:distill_rounds=1`)."""
    parsed = [(arm, *parse_arm(arm)) for arm in arms]
    pairs = []
    for arm, mode, over in parsed:
        zeros = {k for k, v in over.items() if v == 0}
        if not zeros:
            if mode != 'supervised' or over:
                pairs.append((arm_label(arm), 'supervised'))
            continue
        kept = {k: v for k, v in over.items() if k not in zeros}
        for other, other_mode, other_over in parsed:
            if other_mode == mode and all(other_over.get(k, 1) != 0 for k in zeros) and \
                    {k: v for k, v in other_over.items() if k not in zeros} == kept:
                pairs.append((arm_label(other), arm_label(arm)))
    return pairs


def job_key(job):
    """What identifies a finished run in the journal (OUT.runs.jsonl)."""
    count, arm, budget_s, fixed_steps, overrides, seed = job[:6]
    key = [count, arm_label(arm), seed, fixed_steps or f'{budget_s:g} s',
           sorted(overrides.items())]
    if len(job) > 6 and job[6] != 'none':      # also scored with `monet process --filter`
        key.append(f'filter {job[6]}')
    return json.dumps(key)


def read_journal(path):
    """{job_key: row} of the runs already in OUT.runs.jsonl (none when it is missing)."""
    done = {}
    if path.exists():
        for line in path.read_text().splitlines():
            if line.strip():
                entry = json.loads(line)
                done[entry['key']] = entry['row']
    return done


def curve(rows, counts, seeds, arms):
    """Markdown: the learning curve (mean over label sets per count and model) and paired
    differences against supervised and against each exact control."""
    labels = [arm_label(a) for a in arms] + list(dict.fromkeys(
        r['mode'] for r in rows if r['mode'].startswith('peer')))
    by = {(r['labels'], r['seed'], r['mode']): r for r in rows}
    stats = (('median_mm', '3D median', '.0f', 1), ('mean_mm', '3D mean', '.0f', 1),
             ('p90_mm', '3D p90', '.0f', 1), ('pck10', 'PCK@10 px', '.1f', 100))
    method = next((r['filter'] for r in rows if r.get('filter')), None)
    if method:
        stats += tuple((f'filter_{key}', f'--filter {method}: {name}', '.0f', 1)
                       for key, name in (('mean_mm', '3D mean'), ('p90_mm', '3D p90')))
    lines = ['| labelled instants | model | label sets | ' + ' | '.join(
        f'{name} (mean over sets{", mm" if key != "pck10" else ", %"})'
        for key, name, _, _ in stats) + ' |', '|---|---|---|' + '---|' * len(stats)]
    for n in counts:
        for label in labels:
            got = [by[(n, s, label)] for s in seeds if (n, s, label) in by]
            if not got:
                continue
            cells = []
            for key, _, spec, scale in stats:
                vals = [r[key] * scale for r in got if r.get(key) is not None]
                cells.append(format(np.mean(vals), spec) if vals else '–')
            lines.append(f'| {n} | {label} | {len(got)} | ' + ' | '.join(cells) + ' |')
    pairs = paired_arms(arms)
    if pairs:
        filtered = (f' --filter {method}: 3D mean (mm), per set | better on | --filter {method}:'
                    ' 3D p90 (mm), per set | better on |') if method else ''
        lines += ['', '| labelled instants | paired difference | label sets | 3D mean (mm), '
                  'per set | better on | 3D p90 (mm), per set | better on |' + filtered,
                  '|---|---|---|---|---|---|---|' + '---|---|---|---|' * bool(method)]
    for n in counts:
        for a, b in pairs:
            both = [(by[(n, s, a)], by[(n, s, b)]) for s in seeds
                    if (n, s, a) in by and (n, s, b) in by]
            if not both:
                continue
            cells = []
            for key in ('mean_mm', 'p90_mm', *(('filter_mean_mm', 'filter_p90_mm')
                                               if method else ())):
                d = [x[key] - y[key] for x, y in both
                     if x.get(key) is not None and y.get(key) is not None]
                cells += [' / '.join(f'{v:+.0f}' for v in d), f'{sum(v < 0 for v in d)}/{len(d)}']
            lines.append(f'| {n} | {a} - {b} | {len(both)} | ' + ' | '.join(cells) + ' |')
    return '\n'.join(lines)


def baselines(count, seed):
    """Image-blind rows: nearest labelled instant's pose, mean labelled pose."""
    from monet_ros.learning.pseudo_labels import spatial_pseudo_labels

    recording, reference, reference2d = _STATE['recording'], _STATE['reference'], \
        _STATE['reference2d']
    T = recording.num_instants
    instants = choose_instants(T, count, seed)
    labels = np.full_like(recording.labels, np.nan)
    labels[instants] = reference2d[instants]
    X_lab = spatial_pseudo_labels(labels, recording.cameras).points3d       # from the labels
    unlabelled = np.setdiff1d(np.arange(T), instants)
    nearest = instants[np.abs(np.arange(T)[:, None] - instants[None]).argmin(axis=1)]
    rows = []
    for name, X in (('nearest labelled pose', X_lab[nearest]),
                    ('mean labelled pose', np.repeat(np.nanmean(X_lab[instants], axis=0)[None],
                                                     T, axis=0))):
        r = score(X, project_reference(X, recording.cameras), reference, reference2d,
                  unlabelled)
        r.update({'labels': count, 'mode': name, 'steps': 0, 'train_s': 0.0})
        rows.append(r)
    return rows


def openpose_row(root):
    from monet_ros.fusion import FusionConfig

    recording, reference, reference2d = _STATE['recording'], _STATE['reference'], \
        _STATE['reference2d']
    uv, likelihood = load_openpose(root, recording.keypoints, recording.num_views)
    X = fuse(uv, likelihood, recording.cameras, FusionConfig(confidence_threshold=0.3,
                                                             threshold_px=7.5, min_views=2))
    uv = np.where((likelihood >= 0.3)[..., None], uv, np.nan)
    r = score(X, uv, reference, reference2d, np.arange(recording.num_instants))
    r.update({'labels': 0, 'mode': 'OpenPose (pretrained) + fuse_points', 'steps': 0,
              'train_s': 0.0})
    return r


def peer_rows(paths, count, seed, instants):
    """The peer rows (bench/peer.py's OUT.json) of this label set; an error if one of them
    was trained on other instants."""
    rows = []
    for path in paths:
        for r in json.loads(Path(path).read_text()):
            if r['mode'] != 'peer sleap-nn' or (r['labels'], r['seed']) != (count, seed):
                continue
            if r['instants'] != instants.tolist():
                raise SystemExit(f'{path}: its peer row for {count} labels, seed {seed} was '
                                 f'trained on instants {r["instants"]}, not {instants.tolist()}')
            # one name per training budget (its wall time is the table's column): the
            # curve and the plot take every label set's peer row as one model
            budget = f'{r["steps"]} steps' if r.get('steps') else f'{r["train_s"]:.0f} s'
            rows.append(dict(r, mode=f'peer sleap-nn ({budget})'))
    return rows


def fmt(value, spec):
    return '–' if value is None else format(value, spec)


def table(rows):
    lines = ['| labelled instants | seed | model | steps | train wall (s) | 3D median / mean / '
             'p90 (mm) | triangulated | PCK@5 / 10 / 20 px | GT crops: 3D median / mean / '
             'p90 (mm), PCK@10 | fit on labels (px) | warnings |',
             '|---|---|---|---|---|---|---|---|---|---|---|']
    method = next((r['filter'] for r in rows if r.get('filter')), None)
    if method:
        lines[0] += f' `monet process --filter {method}`: 3D median / mean / p90 (mm) |'
        lines[1] += '---|'
    for r in rows:
        g = r.get('gt_crop')
        gt = '–' if g is None else (f'{fmt(g["median_mm"], ".0f")} / {fmt(g["mean_mm"], ".0f")}'
                                    f' / {fmt(g["p90_mm"], ".0f")}, '
                                    f'{fmt(g.get("pck10"), ".1%")}')
        lines.append(
            f'| {r["labels"] or "–"} | {r.get("seed", "–")} | {r["mode"]} | '
            f'{r["steps"] or "–"} | '
            f'{fmt(r["train_s"] or None, ".0f")} | {fmt(r["median_mm"], ".0f")} / '
            f'{fmt(r["mean_mm"], ".0f")} / {fmt(r["p90_mm"], ".0f")} | '
            f'{r["triangulated"]:.0%} | {fmt(r.get("pck5"), ".1%")} / '
            f'{fmt(r.get("pck10"), ".1%")} / {fmt(r.get("pck20"), ".1%")} | {gt} | '
            f'{fmt(r.get("fit_px"), ".1f")} | {len(r.get("warnings", []))} |'
            + (f' {fmt(r.get("filter_median_mm"), ".0f")} / {fmt(r.get("filter_mean_mm"), ".0f")}'
               f' / {fmt(r.get("filter_p90_mm"), ".0f")} |' if method else ''))
    return '\n'.join(lines)


def plot(rows, path, counts):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for mode in (*dict.fromkeys(r['mode'] for r in rows
                                if r['mode'].split(' (')[0] in TRAIN_MODES),
                 *dict.fromkeys(r['mode'] for r in rows if r['mode'].startswith('peer')),
                 'nearest labelled pose'):
        pts = sorted((r['labels'], r['median_mm'], r.get('pck10')) for r in rows
                     if r['mode'] == mode and r['median_mm'] is not None)
        if not pts:
            continue
        # one point per label set (small), the line through their means per count
        counts_here = sorted({p[0] for p in pts})
        mean_3d = [np.mean([p[1] for p in pts if p[0] == n]) for n in counts_here]
        mean_pck = [100 * np.mean([p[2] for p in pts if p[0] == n and p[2] is not None])
                    for n in counts_here]
        style = '--s' if mode not in TRAIN_MODES and ' (' not in mode else '-o'
        line = axes[0].plot(counts_here, mean_3d, style, label=mode)[0]
        axes[1].plot(counts_here, mean_pck, style, label=mode, color=line.get_color())
        if len(pts) > len(counts_here):
            axes[0].plot([p[0] for p in pts], [p[1] for p in pts], '.', alpha=0.4,
                         color=line.get_color())
            have = [p for p in pts if p[2] is not None]
            axes[1].plot([p[0] for p in have], [100 * p[2] for p in have], '.', alpha=0.4,
                         color=line.get_color())
    for r in rows:
        if r['mode'].startswith('OpenPose'):
            axes[1].axhline(100 * r['pck10'], color='grey', ls=':', label='OpenPose')
    axes[0].set(xlabel='labelled instants', ylabel='3D median error (mm)', xticks=counts,
                title='3D error on unlabelled instants')
    axes[1].set(xlabel='labelled instants', ylabel='PCK@10 px (%)', xticks=counts,
                title='2D PCK@10 px on unlabelled instants')
    axes[0].legend()
    axes[1].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--data', type=Path, default=None,
                        help='shared data folder (default: ../shared/data)')
    parser.add_argument('--out', default=None, help='output path stem (default '
                        'bench/results/real, or bench/results/real_quick with --quick)')
    parser.add_argument('--labels', nargs='+', type=int, default=[2, 3, 5, 10],
                        help='numbers of labelled instants')
    parser.add_argument('--modes', nargs='+', default=list(MODES), metavar='MODE[:K=V,...]',
                        help='monet train modes, each with optional TrainConfig overrides '
                             "(reprojection:lambda_r=0 is the default's exact control)")
    parser.add_argument('--budget-s', type=float, default=300.0,
                        help='training wall time per run (s), the same for every mode')
    parser.add_argument('--steps', type=int, default=0,
                        help='equal step counts instead of equal wall time')
    parser.add_argument('--seeds', nargs='+', type=int, default=[0],
                        help='one set of labelled instants (and training seed) per seed')
    parser.add_argument('--jobs', type=int, default=1, help='runs in parallel (processes)')
    parser.add_argument('--set', nargs='*', default=[], metavar='KEY=VALUE',
                        help='TrainConfig overrides for every run (e.g. lr=3e-4)')
    parser.add_argument('--peer', nargs='*', type=Path, default=[], metavar='PEER_JSON',
                        help='OUT.json of bench/peer.py runs: their sleap-nn rows join the '
                             'table where labels and seed match those of this run')
    parser.add_argument('--filter', choices=('none', 'kalman', 'optim'), default='none',
                        help='also score each model through `monet process --filter METHOD` '
                        '(the 3D filter a user can add: columns beside the unfiltered ones)')
    parser.add_argument('--quick', action='store_true',
                        help='smoke run: 3 labelled instants, 45 s per run')
    args = parser.parse_args(argv)
    from monet_ros.learning.recording import load_recording

    if args.quick:
        args.labels, args.budget_s = [3], 45.0
    stem = Path(args.out or REPO / 'bench' / 'results' / ('real_quick' if args.quick
                                                           else 'real'))
    overrides = {}
    for pair in args.set:
        key, sep, value = pair.partition('=')
        if not sep or key not in TrainConfig.__dataclass_fields__:
            parser.error(f'--set {pair!r}: expected KEY=VALUE with KEY a TrainConfig field')
        overrides[key] = parse_value(value)
    for arm in args.modes:
        try:
            parse_arm(arm)
        except ValueError as e:
            parser.error(str(e))
    root = args.data or default_data_root()
    if not (root / BAG).exists():
        print(f'real.py: {root / BAG} not found (use --data){"" if args.data else ": skipped"}',
              file=sys.stderr)
        return 2 if args.data else 0
    start = time.monotonic()
    recording = load_recording(root / BAG, skeleton='human14')
    reference = load_reference(root, recording.keypoints)
    if len(reference) != recording.num_instants:
        raise SystemExit(f'{len(reference)} reference frames for {recording.num_instants} '
                         'instants')
    _STATE.update(recording=recording, reference=reference, bag=root / BAG,
                  reference2d=project_reference(reference, recording.cameras))
    print(f'loaded {recording.num_instants} instants x {recording.num_views} views in '
          f'{time.monotonic() - start:.0f} s', file=sys.stderr)
    jobs = [(n, m, args.budget_s, args.steps, overrides, seed, args.filter)
            for seed in args.seeds for n in args.labels for m in args.modes]
    journal = stem.with_suffix('.runs.jsonl')
    done = read_journal(journal)
    todo = [j for j in jobs if job_key(j) not in done]
    if len(todo) < len(jobs):
        print(f'{len(jobs) - len(todo)} of {len(jobs)} runs already in {journal}: skipped',
              file=sys.stderr)
    stem.parent.mkdir(parents=True, exist_ok=True)

    def record(job, row):           # at once, so a stopped curve keeps its runs
        done[job_key(job)] = row
        with journal.open('a') as f:
            f.write(json.dumps({'key': job_key(job), 'row': row}) + '\n')

    if args.jobs > 1 and todo:
        with ProcessPoolExecutor(args.jobs,
                                 mp_context=multiprocessing.get_context('fork')) as pool:
            futures = {pool.submit(run_job, j): j for j in todo}
            for future in as_completed(futures):
                record(futures[future], future.result())
    else:
        for j in todo:
            record(j, run_job(j))
    trained = [done[job_key(j)] for j in jobs]
    rows = [openpose_row(root)]
    for n in args.labels:
        for seed in args.seeds:
            rows += [r for r in trained if r['labels'] == n and r['seed'] == seed]
            rows += [dict(r, seed=seed) for r in baselines(n, seed)]
            rows += peer_rows(args.peer, n, seed,
                              choose_instants(recording.num_instants, n, seed))
    peers = [r for r in rows if r['mode'].startswith('peer')]
    command = 'python bench/real.py ' + ' '.join(argv if argv is not None else sys.argv[1:])
    title = '# Label efficiency on real video (Pose2Sim 4-camera recording)'
    if args.quick:
        title += ' - QUICK smoke run (45 s per run), not the figures'
    text = '\n'.join([
        title,
        '', f'Command: `{command.strip()}` (wall {time.monotonic() - start:.0f} s, load average '
        f'{os.getloadavg()[0]:.1f} at the end, torch 1 thread per run, {args.jobs} job(s)).',
        f'Budget: {"%d steps" % args.steps if args.steps else "%.0f s" % args.budget_s} per '
        f'run; seeds {args.seeds}; overrides {overrides or "none"}; scores on the unlabelled '
        'instants (OpenPose row: all instants). How the figures are made: bench/real.py.', '',
        table(rows), '',
        *(['## Learning curve', '', curve(trained + peers, args.labels, args.seeds,
                                          args.modes), '']
          if len(args.labels) > 1 or len(args.seeds) > 1 else []),
        'Labelled instants per count: ' + '; '.join(
            f'{n} (seed {seed}): {choose_instants(recording.num_instants, n, seed).tolist()}'
            for n in args.labels for seed in args.seeds), ''])
    warnings = [(r['labels'], r['mode'], w) for r in trained for w in r['warnings']]
    if warnings:
        text += '\nWarnings of the runs:\n\n' + '\n'.join(
            f'- {n} labels, {m}: {w}' for n, m, w in warnings) + '\n'
    stem.with_suffix('.md').write_text(text)
    stem.with_suffix('.json').write_text(json.dumps(rows, indent=1))
    plot(rows, stem.with_suffix('.png'), args.labels)
    print(text)
    return 0


if __name__ == '__main__':
    sys.exit(main())
