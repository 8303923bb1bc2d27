"""`monet eval` says which instants it scores (held out, or the ones the model was trained
on) and counts reprojection errors beyond the image diagonal as failures instead of
averaging them (a badly trained model's triangulation can land 1e15 px away)."""
import json

from helpers.blob_bag import write_blob_folder
from helpers.blobs import blob_recording
from helpers.commands import run_monet_process
import numpy as np
import pytest

from monet_ros.evaluation.pck import pck
from monet_ros.evaluation.report import EvalSummary, markdown_table
from monet_ros.evaluation.reprojection import ErrorStats, multiview_reprojection

TRAIN = ['--architecture', 'small', '--input-size', '48', '--width', '16',
         '--batch-labelled', '2', '--batch-pseudo', '2', '--batch-unlabeled', '1',
         '--views-per-instant', '2', '--mode', 'supervised', '--device', 'cpu',
         '--threads', '1', '--no-progress', '--precision', 'float32']


def monet(repo_root, *args):
    return run_monet_process(repo_root, *args)


def test_errors_beyond_the_image_diagonal_are_failures_counted_apart():
    rec = blob_recording(num_views=3, T=2, C=2, labelled=())
    cams = rec.cameras
    diagonal = np.hypot(cams[0].width, cams[0].height)
    detections = np.stack([[c.project(rec.gt3d[t]) for c in cams] for t in range(2)])
    result = multiview_reprojection(detections, cams, rec.gt3d)
    np.testing.assert_allclose(result.diagonal, [diagonal] * 3)
    # the same arrays with two absurd errors: figures of the others, two failures
    errors = result.consistency.copy()
    errors[0, 1, 0], errors[1, 2, 1] = 1e15, 2 * diagonal
    plain = errors[(errors < diagonal) & np.isfinite(errors)]
    stats = result.capped_stats(errors)
    assert (stats.count, stats.failures) == (plain.size, 2)
    assert stats.mean == pytest.approx(plain.mean()) and stats.mean < 1.0
    assert ErrorStats.of(errors).mean > 1e13              # what averaging them gave
    summary = EvalSummary('supervised', 'blobs', stats.mean, stats.std, 0.0, 0.0,
                          pck(np.zeros((4, 2)), keypoints=('a', 'b')), 2,
                          {'reprojection_failures': 2})
    assert f'{stats.mean:.2f} ± {stats.std:.2f} (+2 failed)' in markdown_table([summary])


@pytest.fixture(scope='module')
def data(tmp_path_factory):
    rec = blob_recording(num_views=4, T=24, C=3, labelled=(2, 9), label_views=(0, 1))
    base = tmp_path_factory.mktemp('eval_scored')
    folder = write_blob_folder(rec, base / 'data')
    skeleton = base / 'blobs.yaml'
    skeleton.write_text('name: blobs\nkeypoints: [k0, k1, k2]\n')
    return folder, skeleton, rec


@pytest.mark.parametrize('fraction', ['0', '0.25'])
def test_eval_says_which_instants_it_scores(data, repo_root, tmp_path, fraction):
    folder, skeleton, rec = data
    run = tmp_path / 'run'
    done = monet(repo_root, 'train', folder, '--out', run, '--skeleton', skeleton, '--steps',
                 2, '--checkpoint-every', 2, '--eval-fraction', fraction, *TRAIN)
    assert done.returncode == 0, done.stderr
    done = monet(repo_root, 'eval', run / 'model.pt', '--data', folder, '--skeleton', skeleton,
                 '--out', tmp_path / 'report', '--device', 'cpu', '--threads', '1')
    assert done.returncode == 0, done.stderr
    said = [line for line in done.stderr.splitlines() if ' instants' in line]
    assert len(said) == 1
    held = int(np.ceil(24 * float(fraction)))
    if held:
        assert said[0] == (f'monet eval: {run / "model.pt"} on data: {held} held-out instants '
                           f'(from instant {24 - held}, never trained on)')
    else:
        assert said[0].startswith(f'monet eval: {run / "model.pt"} on data: all 24 instants, '
                                  'which the model was TRAINED on')
    result, = json.loads((tmp_path / 'report' / 'results.json').read_text())
    extra = result['extra']
    assert result['instants'] == (held or 24)
    assert extra['instants_scored'] == ('held-out' if held else 'training')
    # every triangulated view's error is either in the figures or a counted failure
    diagonal = np.hypot(rec.cameras[0].width, rec.cameras[0].height)
    assert extra['reprojection_count'] + extra['reprojection_failures'] > 0
    assert not np.isfinite(result['reproj_mean_px']) or result['reproj_mean_px'] <= diagonal
