"""`monet train` and `monet eval` end to end in real processes: a small recording folder,
training that survives a SIGKILL and resumes, and the evaluation table."""
import csv
import json
import os
import signal
import subprocess
import sys
import time

from helpers.blob_bag import write_blob_folder
from helpers.blobs import blob_recording
import pytest
import torch

from monet_ros.models import load_checkpoint

TRAIN = ['--architecture', 'small', '--input-size', '48', '--width', '16',
         '--batch-labelled', '4', '--batch-pseudo', '4', '--batch-unlabeled', '1',
         '--views-per-instant', '3', '--lr', '3e-3', '--eval-fraction', '0.25',
         '--device', 'cpu', '--threads', '1', '--no-progress']


def monet(repo_root, *args, **kwargs):
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join(filter(None, [str(repo_root), env.get('PYTHONPATH')]))
    return subprocess.Popen([sys.executable, '-m', 'monet_ros.cli', *map(str, args)],
                            cwd=repo_root, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, **kwargs)


@pytest.fixture(scope='module')
def folder(tmp_path_factory):
    rec = blob_recording(num_views=4, T=24, C=3, labelled=(2, 9), label_views=(0, 1))
    return write_blob_folder(rec, tmp_path_factory.mktemp('blobs') / 'data'), rec


@pytest.mark.slow
def test_train_killed_then_resumed_then_evaluated(folder, repo_root, tmp_path):
    data, rec = folder
    skeleton = tmp_path / 'blobs.yaml'
    skeleton.write_text('name: blobs\nkeypoints: [k0, k1, k2]\n')
    out = tmp_path / 'run'
    args = ['train', data, '--out', out, '--skeleton', skeleton, '--mode', 'monet',
            '--steps', 400, '--checkpoint-every', 5, *TRAIN]
    proc = monet(repo_root, *args)
    state = out / 'trainer_state.pt'
    deadline = time.monotonic() + 90
    while not state.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.2)
    assert proc.poll() is None, proc.communicate()
    assert state.exists(), 'no checkpoint within 90 s'
    time.sleep(0.5)
    proc.send_signal(signal.SIGKILL)
    proc.communicate()
    # trainer_state.pt is the commit point (written last): a kill between the model and
    # state writes resumes from the state's step, with model.pt one checkpoint ahead
    killed_at = torch.load(state, weights_only=True)['step']
    assert killed_at >= 5 and killed_at % 5 == 0
    assert load_checkpoint(out / 'model.pt')[1]['step'] in (killed_at, killed_at + 5)
    for path in out.rglob('*.pt'):             # every visible checkpoint is whole
        if path.name != 'trainer_state.pt':
            load_checkpoint(path)

    args[args.index('--steps') + 1] = killed_at + 5
    proc = monet(repo_root, *args, '--resume')
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 0, stderr
    assert f'resumed at step {killed_at}' in stderr
    assert not list(out.rglob('.*.tmp')), 'resume removes temporary files of the killed run'
    summary = json.loads(stdout)
    assert summary['steps'] == killed_at + 5
    with open(out / 'train_log.csv') as f:
        steps = [int(r['step']) for r in csv.DictReader(f)]
    assert steps == list(range(1, killed_at + 6))
    meta = load_checkpoint(out / 'model.pt')[1]
    assert meta['step'] == killed_at + 5 and meta['recording'] == 'data'

    report = tmp_path / 'report'
    proc = monet(repo_root, 'eval', out / 'model.pt', '--data', data, '--skeleton', skeleton,
                 '--out', report, '--threads', 1)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 0, stderr
    lines = stdout.strip().splitlines()
    assert lines[0].startswith('| Mode | data reproj. (px) | data vs GT (px) | data PCK@0.05')
    assert lines[2].startswith('| MONET | ')
    with open(report / 'results.csv') as f:
        row = next(csv.DictReader(f))
    assert row['mode'] == 'monet' and int(row['instants']) == 6     # the held-out tail
    assert 0.0 <= float(row['pck@0.20']) <= 1.0
    assert float(row['reproj_mean_px']) >= 0.0
    assert (report / 'pck_data.png').stat().st_size > 1000


def test_bad_arguments_are_named(folder, repo_root, tmp_path):
    data, _ = folder
    proc = monet(repo_root, 'train', data, '--out', tmp_path, '--lambda-e', '-1')
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 2 and 'lambda_e' in stderr
    proc = monet(repo_root, 'eval', tmp_path / 'missing.pt', '--data', data, '--out', tmp_path,
                 '--skeleton', 'human14')
    _, stderr = proc.communicate(timeout=60)
    # the data's labels name keypoints k0..k2, not human14's: one line naming the file
    assert proc.returncode == 2 and "labels.csv:2: field keypoint: 'k0'" in stderr
    assert 'Traceback' not in stderr and len(stderr.strip().splitlines()) == 1


def test_resume_without_a_state_says_so_and_the_start_line_names_the_loss(folder, repo_root,
                                                                          tmp_path):
    data, _ = folder
    skeleton = tmp_path / 'blobs.yaml'
    skeleton.write_text('name: blobs\nkeypoints: [k0, k1, k2]\n')
    out = tmp_path / 'run'
    proc = monet(repo_root, 'train', data, '--out', out, '--skeleton', skeleton, '--steps', 4,
                 '--epipolar-warmup', '0.5', *TRAIN, '--resume')
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 0, stderr
    assert f'nothing to resume: no {out / "trainer_state.pt"}' in stderr
    assert 'mode reprojection (L_L + 1 L_B + 1 L_R from step 2)' in stderr     # the default
    assert json.loads(stdout)['last']['step'] == 4


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_a_signal_keeps_every_step_trained_and_resume_continues(folder, repo_root, tmp_path,
                                                               signum):
    """SIGINT / SIGTERM mid-training: exit 0 with a checkpoint of the last finished step
    (not the last scheduled one: --checkpoint-every is far away), and --resume goes on
    from it."""
    data, _ = folder
    skeleton = tmp_path / 'blobs.yaml'
    skeleton.write_text('name: blobs\nkeypoints: [k0, k1, k2]\n')
    out = tmp_path / 'run'
    args = ['train', data, '--out', out, '--skeleton', skeleton, '--steps', 100000,
            '--checkpoint-every', 50000, *TRAIN]
    proc = monet(repo_root, *args)
    log = out / 'train_log.csv'
    deadline = time.monotonic() + 120
    while proc.poll() is None and time.monotonic() < deadline and \
            (not log.exists() or len(log.read_text().splitlines()) < 4):
        time.sleep(0.1)
    assert proc.poll() is None, proc.communicate()
    proc.send_signal(signum)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 0, stderr
    state = torch.load(out / 'trainer_state.pt', weights_only=True)
    rows = log.read_text().splitlines()[1:]
    assert state['step'] == len(rows) >= 3            # every logged step is in the state
    assert load_checkpoint(out / 'model.pt')[1]['step'] == state['step']
    assert f'after step {state["step"]}: wrote' in stderr and 'Traceback' not in stderr
    args[args.index('--steps') + 1] = state['step'] + 2
    proc = monet(repo_root, *args, '--resume')
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 0, stderr
    assert f'resumed at step {state["step"]}' in stderr
    assert json.loads(stdout)['last']['step'] == state['step'] + 2
