"""`monet pipeline --learn` in a real process: the learner trains beside the live pipeline,
its announced checkpoints are hot-reloaded by the detector, each validated checkpoint prints
the live reprojection error, and the run ends cleanly."""
import subprocess
import sys
import time

from helpers.blob_bag import write_blob_folder
from helpers.blobs import blob_recording
import torch

from monet_ros.models import build_model, load_checkpoint, save_checkpoint


def test_pipeline_learn_announces_and_the_detector_reloads(repo_root, ros_env, tmp_path):
    rec = blob_recording(num_views=4, T=24, C=3, labelled=(2, 9), label_views=(0, 1))
    folder = write_blob_folder(rec, tmp_path / 'data', camera_info=True)
    (tmp_path / 'blobs.yaml').write_text('name: blobs\nkeypoints: [k0, k1, k2]\n')
    torch.manual_seed(0)
    save_checkpoint(tmp_path / 'init.pt', build_model('small', 3, input_size=[48, 48],
                                                      width=16), {'keypoints': ['k0', 'k1', 'k2']})
    out = tmp_path / 'learner'
    # every finite checkpoint is announced (the criterion is tested in test_online.py)
    proc = subprocess.run(
        [sys.executable, '-m', 'monet_ros.cli', 'pipeline', '--bag', str(folder / 'recording'),
         '--rig', str(folder / 'rig.yaml'), '--model', str(tmp_path / 'init.pt'),
         '--skeleton', str(tmp_path / 'blobs.yaml'), '--loop', '--rate', '0.3', '--quiet',
         '--device', 'cpu', '--duration', '45', '--learn', '--learn-every', '2',
         '--learn-lr', '3e-3', '--learn-tolerance-px', '1e6', '--learn-out', str(out)],
        cwd=repo_root, env=ros_env, capture_output=True, text=True, timeout=400)
    output = proc.stdout + proc.stderr
    assert proc.returncode == 0, output
    lines = [line for line in proc.stdout.splitlines() if line.startswith('learner: step ')]
    assert lines and all('live reprojection with the previous weights' in line
                         for line in lines), output
    assert any(' announced (held-out reprojection ' in line for line in lines), output
    assert 'loaded new weights' in output and str(out / 'checkpoints') in output, output
    steps = [int(line.split()[2]) for line in lines]
    assert steps == sorted(steps) and all(s % 2 == 0 for s in steps)
    assert load_checkpoint(out / 'model.pt')[1]['keypoints'] == ['k0', 'k1', 'k2']
    assert any(line.startswith('monet pipeline: ') for line in proc.stdout.splitlines())


def test_the_learner_line_says_what_a_missing_metric_means(capsys):
    """One labelled instant (none can be held out: the criterion falls back to the
    reprojection error): the line read 'held-out labelled error None px'."""
    from monet_ros.commands.pipeline import Summary
    from monet_ros.commands.pipeline_learn import AnnouncementLog
    from monet_ros.learning.online import CheckpointResult

    summary = Summary()
    log = AnnouncementLog(summary)
    summary.errors.append((time.monotonic(), 2.0))    # a frame fused before the first line
    log(CheckpointResult('ck.pt', 4, 'ab', {'reprojection_px': 1.234}, True, 'first'))
    log(CheckpointResult('ck.pt', 6, 'cd', {'reprojection_px': float('nan'),
                                            'labelled_mean_px': 3.456}, False, 'worse'))
    lines = capsys.readouterr().out.splitlines()
    assert lines == [
        'learner: step 4 announced (held-out reprojection 1.23 px, held-out labelled error '
        'none (no labelled instant held out): first); live reprojection with the previous '
        'weights: 2.00 px over 1 frames',
        'learner: step 6 kept back (held-out reprojection none (no held-out instant '
        'triangulated), held-out labelled error 3.46 px: worse); live reprojection with the '
        'previous weights: no frames']


def test_learn_tolerance_help_names_the_criterion():
    import argparse

    from monet_ros.commands.pipeline_learn import add_learn_arguments

    parser = argparse.ArgumentParser()
    add_learn_arguments(parser)
    text = ' '.join(next(a for a in parser._actions
                         if a.dest == 'learn_tolerance_px').help.split())
    assert 'held-out labelled error' in text and 'by default' in text
    assert 'held-out reprojection error when no labelled instant can be held out' in text
