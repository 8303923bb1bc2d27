"""What `monet train` says, in real processes on a small blob recording folder: the skeleton
it trains (one line at start), a resume with another skeleton (one line naming both, before
any network is built), a pickled file refused as unsafe (never torch's advice to load it
with weights_only=False) and the no-labels error (no contradiction about --eval-fraction)."""
import fractions

from helpers.blob_bag import write_blob_folder
from helpers.blobs import blob_recording
from helpers.commands import run_monet_process
import pytest
import torch

from monet_ros.models import CheckpointError, load_checkpoint
from monet_ros.share import share_path
from monet_ros.skeleton import load_skeleton

TRAIN = ['--architecture', 'small', '--input-size', '48', '--width', '16',
         '--batch-labelled', '2', '--batch-pseudo', '2', '--batch-unlabeled', '1',
         '--views-per-instant', '2', '--mode', 'supervised', '--device', 'cpu',
         '--threads', '1', '--no-progress']


def monet(repo_root, *args):
    return run_monet_process(repo_root, *args)


@pytest.fixture(scope='module')
def trained(tmp_path_factory, repo_root):
    """A blob folder (keypoints k0 k1 k2) and a 2-step run on skeleton `mouse3`."""
    base = tmp_path_factory.mktemp('train_messages')
    rec = blob_recording(num_views=4, T=24, C=3, labelled=(2, 9), label_views=(0, 1))
    data = write_blob_folder(rec, base / 'data')
    mouse3 = base / 'mouse3.yaml'
    mouse3.write_text('name: mouse3\nkeypoints: [k0, k1, k2]\n')
    out = base / 'run'
    done = monet(repo_root, 'train', data, '--out', out, '--skeleton', mouse3, '--steps', 2,
                 '--checkpoint-every', 2, *TRAIN)
    assert done.returncode == 0, done.stderr
    return data, mouse3, out, done


def test_the_skeleton_trained_is_named_at_start(trained, repo_root, tmp_path):
    data, mouse3, out, done = trained
    said = [line for line in done.stderr.splitlines() if 'skeleton' in line]
    assert said == [f'monet train: skeleton mouse3 ({mouse3}), 3 keypoints: k0, k1, k2 '
                    '(--skeleton to choose another)']
    assert load_checkpoint(out / 'model.pt')[1]['keypoints'] == ['k0', 'k1', 'k2']
    # no --skeleton: labels of other keypoints (k0..k2) are one error line that says the
    # human preset was used, with its file and keypoint count
    human = monet(repo_root, 'train', data, '--out', tmp_path / 'human', '--steps', 1, *TRAIN)
    assert human.returncode == 2
    preset = share_path('config', 'skeletons', 'human14.yaml')
    count = len(load_skeleton(preset).keypoints)
    line, = human.stderr.splitlines()
    assert "'k0' is not a keypoint of the skeleton" in line
    assert line.endswith(f'[skeleton human14 (preset {preset}), {count} keypoints: head, neck, '
                         'r_shoulder, r_elbow, r_wrist, l_shoulder, l_elbow, l_wrist, ... '
                         '(--skeleton to choose another)]')
    assert count == 14


def test_resume_with_another_skeleton_is_one_line_naming_both(trained, repo_root, tmp_path):
    data, mouse3, out, _ = trained
    mouse2 = tmp_path / 'mouse2.yaml'
    mouse2.write_text('name: mouse2\nkeypoints: [k0, k1]\n')
    done = monet(repo_root, 'train', data, '--out', out, '--skeleton', mouse2, '--steps', 4,
                 '--resume', '--skip-bad-labels', *TRAIN)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.splitlines()
    assert lines[-1] == (f'monet train: error: {out / "trainer_state.pt"}: --resume: the saved '
                         'run trained skeleton mouse3 (3 keypoints: k0, k1, k2), this run has '
                         'skeleton mouse2 (2 keypoints: k0, k1); give the same --skeleton or a '
                         'new --out')
    assert len(done.stderr.splitlines()) == 1
    assert 'size mismatch' not in done.stderr and 'internal error' not in done.stderr
    # a state written before states named their keypoints: model.pt's keypoints say
    old = tmp_path / 'old'
    old.mkdir()
    state = torch.load(out / 'trainer_state.pt', weights_only=True)
    del state['keypoints'], state['skeleton']
    torch.save(state, old / 'trainer_state.pt')
    (old / 'model.pt').write_bytes((out / 'model.pt').read_bytes())
    done = monet(repo_root, 'train', data, '--out', old, '--skeleton', mouse2, '--steps', 4,
                 '--resume', '--skip-bad-labels', *TRAIN)
    assert done.returncode == 2
    assert done.stderr.splitlines()[-1].endswith(
        'the saved run trained skeleton (3 keypoints: k0, k1, k2), this run has skeleton '
        'mouse2 (2 keypoints: k0, k1); give the same --skeleton or a new --out')


def test_pickled_files_are_refused_as_unsafe_without_torch_advice(trained, repo_root,
                                                                  tmp_path):
    data, mouse3, out, _ = trained
    run = tmp_path / 'pickled'
    run.mkdir()
    state = torch.load(out / 'trainer_state.pt', weights_only=True)
    state['anything'] = fractions.Fraction(1, 3)       # a Python object: pickled code path
    torch.save(state, run / 'trainer_state.pt')
    done = monet(repo_root, 'train', data, '--out', run, '--skeleton', mouse3, '--steps', 4,
                 '--resume', *TRAIN)
    assert done.returncode == 2, done.stderr
    assert done.stderr.splitlines()[-1] == (
        f'monet train: error: {run / "trainer_state.pt"}: not a monet trainer state: it holds '
        'pickled Python objects (fractions.Fraction), which are unsafe to load (they can run '
        'code); refused')
    assert 'weights_only' not in done.stderr
    # a checkpoint the same: every command reading a model meets load_checkpoint
    meta_and_weights = torch.load(out / 'model.pt', weights_only=True)
    meta_and_weights['metadata']['extra'] = fractions.Fraction(1, 3)
    torch.save(meta_and_weights, tmp_path / 'pickled.pt')
    with pytest.raises(CheckpointError) as raised:
        load_checkpoint(tmp_path / 'pickled.pt')
    assert str(raised.value) == (
        f'{tmp_path / "pickled.pt"}: not a monet checkpoint: it holds pickled Python objects '
        '(fractions.Fraction), which are unsafe to load (they can run code); refused')
    done = monet(repo_root, 'eval', tmp_path / 'pickled.pt', '--data', data, '--skeleton',
                 mouse3, '--out', tmp_path / 'report', '--device', 'cpu')
    assert done.returncode == 2 and 'weights_only' not in done.stderr
    assert 'unsafe to load' in done.stderr.splitlines()[-1]


def test_no_labels_error_says_what_is_missing(trained, repo_root, tmp_path):
    data, mouse3, _, _ = trained
    empty = tmp_path / 'labels.csv'
    empty.write_text('stamp_ns,camera,keypoint,u,v\n')
    done = monet(repo_root, 'train', data, '--out', tmp_path / 'run', '--labels', empty,
                 '--skeleton', mouse3, '--steps', 2, *TRAIN)
    assert done.returncode == 2
    line = done.stderr.splitlines()[-1]
    assert line == ('monet train: error: data: no labelled instant to train on; the labels have '
                    'no instant of this recording: give --labels (or a labels.csv beside the '
                    'recording)')
    # labels only in the tail that --eval-fraction holds out: the error says so, once
    rows = (data / 'labels.csv').read_text().splitlines()
    stamp = rows[1].split(',')[0]
    tail = str(10**18 + 20 * 33_000_000)              # instant 20 of the blob recording
    late = tmp_path / 'late.csv'
    late.write_text('\n'.join([rows[0]] + [r.replace(stamp, tail) for r in rows[1:]
                                            if r.startswith(stamp)]) + '\n')
    done = monet(repo_root, 'train', data, '--out', tmp_path / 'tail', '--labels', late,
                 '--skeleton', mouse3, '--steps', 2, *TRAIN, '--eval-fraction', '0.25')
    assert done.returncode == 2
    assert done.stderr.splitlines()[-1].endswith(
        'no labelled instant to train on; 1 labelled instants (indices [20]) of 24, 1 of them '
        'in the last 25% of the instants, held out by --eval-fraction 0.25 (the default 0 '
        'trains on every instant)')


def test_training_into_a_run_without_resume_is_refused(trained, repo_root):
    """`monet train --out RUN` again without --resume replaced RUN's model.pt and
    trainer_state.pt by a new run's and mixed the two runs' checkpoints/: now exit 2, one
    line naming --out and what it holds, and the run left as it was; --resume continues."""
    data, mouse3, out, _ = trained
    before = {p.name: p.read_bytes() for p in out.rglob('*.pt')}
    again = monet(repo_root, 'train', data, '--out', out, '--skeleton', mouse3, '--steps', 1,
                  *TRAIN)
    assert again.returncode == 2, again.stderr
    line, = again.stderr.splitlines()
    assert line == (f"monet train: error: --out: parameter 'out': {out}: holds a training run "
                    '(model.pt, trainer_state.pt); not overwriting: --resume continues it, or '
                    'choose a new folder')
    assert {p.name: p.read_bytes() for p in out.rglob('*.pt')} == before
