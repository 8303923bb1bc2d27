"""Distillation rounds of `monet train --distill-rounds N` (issue 36 item 2).

After its steps the trainer's detector is the teacher: it runs over the training recording
exactly as `monet process --filter optim` runs a model (the detector node's tracked crops,
the fusion, the offline filter with bones, smoothness and robust reprojection); the filtered
3D is reprojected into every view as pseudo-labels (learning.distill.distilled_labels:
weighted and gated by the filter's reprojection error) and training goes on for
distill_round_steps more steps with their crops (L_D, the plan's 'D' part). Each round's
teacher checkpoint and `monet process` output stay in OUT/distill/ for inspection.

The exact control of a distillation run is the same run at lambda_d 0: the same rounds,
teacher runs and crops, no L_D.
"""
import shutil
import sys

import numpy as np


def _say(line):
    print(f'monet train: {line}', file=sys.stderr, flush=True)


def train_with_distillation(trainer, bag, rig=None, camera_map=(), rig_units=None,
                            skeleton=None, progress=True, say=_say):
    """Train `trainer` to config.steps, then its config.distill_rounds rounds (resumes in
    the round trainer.distill_round where a resumed trainer stands). bag: the training
    recording (rosbag2 folder / .mcap) for the teacher's `monet process` run; rig,
    camera_map, rig_units, skeleton: as `monet process` takes them (skeleton: preset or
    YAML, for the filter's bone term). Returns the last Trainer.run summary with `distill`:
    a list of each round's figures (distill_round)."""
    c = trainer.config
    rounds = []
    while True:
        end = c.steps + trainer.distill_round * c.distill_round_steps
        summary = trainer.run(end, progress=progress)
        if trainer.distill_round >= c.distill_rounds:
            break
        rounds.append(distill_round(trainer, trainer.distill_round + 1, bag, rig=rig,
                                    camera_map=camera_map, rig_units=rig_units,
                                    skeleton=skeleton, progress=progress, say=say))
    summary['distill'] = rounds
    return summary


def distill_round(trainer, index, bag, rig=None, camera_map=(), rig_units=None, skeleton=None,
                  progress=True, say=_say):
    """Round `index` (1-based): the teacher's checkpoint (OUT/distill/teacher_<index>.pt),
    its `monet process --filter optim` run over `bag` (OUT/distill/round_<index>/), the
    distilled pseudo-labels set on the trainer. Returns the round's figures (counts of
    learning.distill.Distilled, frames, seconds, median weight)."""
    from monet_ros.commands.process import ProcessConfig, process_recording
    from monet_ros.learning.distill import align_to_instants, distilled_labels
    from monet_ros.models import save_checkpoint
    from monet_ros.temporal import FilterConfig

    c = trainer.config
    if trainer.out_dir is None:
        raise ValueError('distillation rounds need an output folder (the teacher checkpoint '
                         'and its monet process run are written there)')
    folder = trainer.out_dir / 'distill'
    run_dir = folder / f'round_{index}'
    if run_dir.exists():          # a round killed before it trained: run it again
        shutil.rmtree(run_dir)
    teacher = folder / f'teacher_{index}.pt'
    save_checkpoint(teacher, trainer.model, trainer.metadata())
    process = ProcessConfig()
    filter_config = FilterConfig(method='optim',
                                 confidence_threshold=process.confidence_threshold,
                                 threshold_px=process.threshold_px)
    say(f'distillation round {index} of {c.distill_rounds} at step {trainer.step_count}: '
        f'the detector runs over {bag} as `monet process --filter optim` -> {run_dir}')
    figures = process_recording(bag, teacher, run_dir, rig=rig, config=process,
                                device=str(trainer.device), skeleton=skeleton,
                                progress=progress, exports=('csv',), camera_map=camera_map,
                                precision=trainer.precision, filter_config=filter_config,
                                rig_units=rig_units)
    data = trainer.data
    recording = data.recording
    T, V, C, _ = data.labels.shape
    smoothed = figures['filter']
    if smoothed is None:
        X, error, ncams = (np.full((0, C, 3), np.nan), np.zeros((0, C)), np.zeros((0, C)))
        stamps = np.zeros(0, np.int64)
    else:
        X, error, ncams = smoothed.X, smoothed.error, smoothed.ncams
        stamps = figures['filter_stamps']
    X, matched = align_to_instants(recording.stamps, stamps, X)
    error = align_to_instants(recording.stamps, stamps, error)[0]
    ncams = align_to_instants(recording.stamps, stamps, ncams, fill=0)[0]
    train = np.zeros(T, bool)
    train[data.train] = True
    train[data.validation_instants] = False
    cells = ~np.isfinite(data.labels[..., 0]) & train[:, None, None]
    distilled = distilled_labels(X, error, ncams, recording.cameras, cells,
                                 units=figures['units'], gate_px=c.distill_gate_px,
                                 min_views=c.distill_min_views,
                                 residual_px=c.distill_residual_px, matched=matched)
    trainer.set_distilled(distilled.points, distilled.weight, index)
    kept = distilled.weight[distilled.weight > 0]
    stats = {'round': index, 'step': trainer.step_count, 'teacher': str(teacher),
             'process': str(run_dir), 'frames': figures['frames'],
             'process_seconds': round(figures['seconds'], 1),
             'median_weight': float(np.median(kept)) if kept.size else None,
             **distilled.counts}
    say(f'distillation round {index}: {distilled.summary()}; median weight '
        f'{stats["median_weight"] if kept.size else 0:.2f}; training steps '
        f'{trainer.step_count + 1}-{trainer.step_count + c.distill_round_steps} with '
        f'{c.batch_distill} distilled crops per step'
        + ('' if c.lambda_d else ' at lambda_d 0 (the exact control: no L_D)'))
    if distilled.count == 0 and c.lambda_d:
        trainer.warn(f'distillation round {index} kept no pseudo-label ({distilled.summary()}): '
                     "L_D gets no data this round (check the teacher's output in "
                     f'{run_dir}, or raise distill_gate_px / lower distill_min_views)')
    return stats

