"""`monet train --distill-rounds` end to end in a real process: the teacher runs over the
recording as `monet process --filter optim`, its filtered 3D becomes pseudo-labels near the
truth, training goes on with them, and the state keeps the round."""
import csv
import json

import cv2
from helpers.blob_bag import write_blob_folder
from helpers.blobs import blob_recording
import numpy as np
import pytest
import torch

from monet_ros.models import load_checkpoint

from .test_train_eval_commands import TRAIN, monet


@pytest.fixture(scope='module')
def folder(tmp_path_factory):
    rec = blob_recording(num_views=4, T=24, C=3, labelled=(2, 9), label_views=(0, 1))
    return write_blob_folder(rec, tmp_path_factory.mktemp('blobs') / 'data'), rec


def projected_truth(rec):
    out = []
    for cam in rec.cameras:
        rvec = cv2.Rodrigues(np.asarray(cam.R, np.float64))[0]
        p, _ = cv2.projectPoints(rec.gt3d.reshape(-1, 1, 3), rvec, np.asarray(cam.t, float),
                                 np.asarray(cam.K, float), np.asarray(cam.dist, float))
        out.append(p.reshape(rec.gt3d.shape[0], -1, 2))
    return np.stack(out, axis=1)                                          # (T, V, C, 2)


@pytest.mark.slow
def test_a_distillation_round_trains_on_the_teachers_filtered_3d(folder, repo_root, tmp_path):
    data, rec = folder
    skeleton = tmp_path / 'blobs.yaml'
    skeleton.write_text('name: blobs\nkeypoints: [k0, k1, k2]\nbones: [[k0, k1], [k1, k2]]\n')
    out = tmp_path / 'run'
    proc = monet(repo_root, 'train', data, '--out', out, '--skeleton', skeleton,
                 '--steps', 120, '--distill-rounds', 1, '--distill-steps', 20,
                 '--distill-min-views', 2, '--precision', 'float32', *TRAIN)
    stdout, stderr = proc.communicate(timeout=400)
    assert proc.returncode == 0, stderr
    assert 'distillation round 1 of 1 at step 120' in stderr
    summary = json.loads(stdout)
    assert summary['steps'] == 140 and summary['distill_round'] == 1
    (stats,) = summary['distill']
    assert stats['frames'] == 24 and stats['kept'] > 0
    assert stats['kept'] == summary['distilled_labels']
    assert stats['kept'] + stats['no_3d'] + stats['few_views'] + stats['high_error'] + \
        stats['outside'] == stats['cells']
    # the teacher and what its monet process run wrote stay for inspection
    assert load_checkpoint(out / 'distill' / 'teacher_1.pt')[1]['step'] == 120
    assert list((out / 'distill' / 'round_1').glob('*.mcap'))
    assert (out / 'distill' / 'round_1' / 'keypoints3d.csv').is_file()
    # the pseudo-labels trained on are near the projected ground truth (a fitted teacher)
    state = torch.load(out / 'trainer_state.pt', weights_only=True)
    assert state['distill_round'] == 1
    distilled = state['distilled'].numpy()
    err = np.linalg.norm(distilled - projected_truth(rec), axis=-1)
    err = err[np.isfinite(err)]
    assert err.size == stats['kept'] and np.median(err) < 3.0, np.median(err)
    with open(out / 'train_log.csv') as f:
        rows = list(csv.DictReader(f))
    assert [int(r['step']) for r in rows] == list(range(1, 141))
    assert all(r['D'] == '' for r in rows[:120]) and all(float(r['D']) > 0 for r in rows[120:])


# a stop signal that lands while a round's teacher runs (`monet process` over the
# recording): sent by the process itself as the teacher run starts, so it lands there on
# every run whatever the machine's speed
INTERRUPTED_TEACHER = """
import os, signal, sys
import monet_ros.commands.process as process
teacher_run = process.process_recording
def interrupted(*args, **kwargs):
    os.kill(os.getpid(), signal.{sig})
    return teacher_run(*args, **kwargs)
process.process_recording = interrupted
from monet_ros.cli import console_main
sys.argv[0] = 'monet'
console_main()
"""


@pytest.mark.slow
@pytest.mark.parametrize('sig', ['SIGINT', 'SIGTERM'])
def test_a_stop_during_the_teacher_run_keeps_the_training_and_resume_runs_the_round(
        folder, repo_root, tmp_path, sig):
    import os
    import subprocess
    import sys

    data, _ = folder
    skeleton = tmp_path / 'blobs.yaml'
    skeleton.write_text('name: blobs\nkeypoints: [k0, k1, k2]\nbones: [[k0, k1], [k1, k2]]\n')
    out = tmp_path / 'run'
    args = ['train', data, '--out', out, '--skeleton', skeleton, '--steps', 60,
            '--distill-rounds', 1, '--distill-steps', 10, '--distill-min-views', 2,
            '--precision', 'float32', *TRAIN]
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join(filter(None, [str(repo_root), env.get('PYTHONPATH')]))
    proc = subprocess.run([sys.executable, '-c', INTERRUPTED_TEACHER.format(sig=sig),
                           *map(str, args)], cwd=repo_root, env=env, capture_output=True,
                          text=True, timeout=400)
    assert proc.returncode == 0, proc.stderr
    assert 'Traceback' not in proc.stderr
    assert ('stopped during distillation round 1 (its teacher run) at step 60: wrote '
            f'{out / "checkpoints" / "step_000060.pt"} and {out / "trainer_state.pt"} '
            '(--resume runs the round again)') in proc.stderr, proc.stderr
    state = torch.load(out / 'trainer_state.pt', weights_only=True)
    assert state['step'] == 60 and state['distill_round'] == 0
    # --resume runs the round from the teacher on and finishes the run
    resumed = monet(repo_root, *args, '--resume')
    stdout, stderr = resumed.communicate(timeout=400)
    assert resumed.returncode == 0, stderr
    assert 'resumed at step 60' in stderr and 'distillation round 1 of 1 at step 60' in stderr
    summary = json.loads(stdout)
    assert summary['steps'] == 70 and summary['distill_round'] == 1
