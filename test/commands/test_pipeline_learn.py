"""`monet pipeline --learn` in a real process: the learner trains beside the live pipeline,
its announced checkpoints are hot-reloaded by the detector, each validated checkpoint prints
the live reprojection error, and the run ends cleanly."""
import subprocess
import sys

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
