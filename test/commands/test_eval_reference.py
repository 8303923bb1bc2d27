"""`monet eval --reference`: one row per checkpoint, figures equal to an independent
scoring of `monet process`'s own 2D detections against the labels."""
import csv

from helpers.recordings import noise_recording, small_checkpoint
from helpers.scenes import cv2_project
import numpy as np
import pytest

from monet_ros.cli import main as monet
from monet_ros.labels import label_rows, write_labels
from monet_ros.skeleton import load_skeleton


def test_eval_reference_one_row_per_checkpoint(tmp_path, capsys):
    rig, stamps = noise_recording(tmp_path / 'rec', cameras=3, frames=4)
    models = [small_checkpoint(tmp_path / f'm{s}.pt', seed=s) for s in (0, 1)]
    keypoints = load_skeleton('human14').keypoints
    rng = np.random.default_rng(3)
    uv = rng.uniform([0, 0], [319, 239], (2, 3, 14, 2))
    write_labels(tmp_path / 'labels.csv', label_rows([stamps[0], stamps[2]],
                                                      [c.name for c in rig], keypoints, uv))
    code = monet(['eval', *map(str, models), '--data', str(tmp_path / 'rec'), '--reference',
                  str(tmp_path / 'labels.csv'), '--out', str(tmp_path / 'report'),
                  '--px-thresholds', '50,100'])
    out = capsys.readouterr().out
    assert code == 0
    assert 'labels.csv (2d, ' in out and '84 labelled views' in out
    # the line says the precision and backend the models run with: monet process's default
    from monet_ros.commands.common import precision_note
    assert f"monet eval: {precision_note('monet eval', 'auto', 'auto')[1]}" in out, out
    with open(tmp_path / 'report' / 'reference.csv') as f:
        rows = list(csv.DictReader(f))
    assert [r['checkpoint'] for r in rows] == [str(m) for m in models]
    for model, row in zip(models, rows):
        # independent: process the recording, read its 2D detections, measure by hand
        out_dir = tmp_path / f'proc_{model.stem}'
        assert monet(['process', str(tmp_path / 'rec'), '--model', str(model), '--out',
                      str(out_dir), '--quiet', '--export', 'npz']) == 0
        det = np.load(out_dir / 'detections2d.npz')
        index = [det['stamps_ns'].tolist().index(s) for s in (stamps[0], stamps[2])]
        d = np.linalg.norm(det['points2d'][index] - uv, axis=-1).ravel()
        d = np.where(np.isfinite(d), d, np.inf)
        assert float(row['px_median']) == np.median(d)
        assert float(row['pck2d@50px']) == np.mean(d <= 50)
        assert float(row['pck2d@100px']) == np.mean(d <= 100)
    capsys.readouterr()
    assert monet(['eval', str(models[0]), '--data', str(tmp_path / 'rec'), '--reference',
                  str(tmp_path / 'nope.trc'), '--out', str(tmp_path / 'r2')]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_eval_3d_reference_at_another_rate_scores_its_projection(tmp_path, capsys):
    """A 25 Hz TRC on the 30.3 Hz recording: put on the instants by time (linear, said
    so), projected into the cameras for 2D PCK (figures equal to an independent OpenCV
    projection of np.interp'd points against `monet process`'s own detections), the
    labelled instant of the training labels not scored (and listed), unless
    --include-labelled."""

    from helpers.recordings import PERIOD

    from monet_ros.io.export_tables import write_trc

    rig, stamps = noise_recording(tmp_path / 'rec', cameras=3, frames=4)
    model = small_checkpoint(tmp_path / 'm.pt', seed=0)
    keypoints = load_skeleton('human14').keypoints
    rng = np.random.default_rng(4)
    t_ref = np.arange(4) / 25.0
    X_ref = np.array([0.0, 0.0, 1.0]) + rng.uniform(-0.2, 0.2, (4, 14, 3)) \
        + t_ref[:, None, None] * np.array([0.5, 0.0, 0.0])
    write_trc(tmp_path / 'ref.trc', [k.upper() for k in keypoints],
              10**18 + np.round(t_ref * 1e9).astype(np.int64), X_ref)
    write_labels(tmp_path / 'train.csv', label_rows([stamps[1]], [rig[0].name], keypoints,
                                                     np.full((1, 1, 14, 2), 50.0)))
    kmap = ','.join(f'{k.upper()}={k}' for k in keypoints)
    args = ['eval', str(model), '--data', str(tmp_path / 'rec'), '--reference',
            str(tmp_path / 'ref.trc'), '--keypoint-map', kmap, '--labels',
            str(tmp_path / 'train.csv'), '--px-thresholds', '5,50']
    assert monet(args + ['--out', str(tmp_path / 'report')]) == 0
    out = capsys.readouterr().out
    assert "reference time: 25 Hz resampled to the recording's 30.3 Hz by linear " \
        'interpolation in time between neighbouring rows; 4 rows, 1 outside' in out   # 120 ms
    assert '; 2D: its projection into the 3 cameras' in out
    assert 'scored instants: 3 of 4 (0, 2-3); not scored: 1 labelled in' in out
    with open(tmp_path / 'report' / 'reference_instants.csv') as f:
        assert [r['status'] for r in csv.DictReader(f)] == ['scored', 'labelled', 'scored',
                                                             'scored']
    with open(tmp_path / 'report' / 'reference.csv') as f:
        row = next(csv.DictReader(f))
    assert row['points2d_from'] == 'projection' and int(row['instants_scored']) == 3
    # independent: interpolate, project with OpenCV, measure against process's detections
    t_rec = (np.asarray(stamps) - stamps[0]) / 1e9
    assert np.allclose(np.diff(t_rec), PERIOD / 1e9)
    X = np.stack([np.stack([[np.interp(t, t_ref, X_ref[:, c, d]) for d in range(3)]
                            for c in range(14)]) for t in t_rec])
    assert monet(['process', str(tmp_path / 'rec'), '--model', str(model), '--out',
                  str(tmp_path / 'proc'), '--quiet', '--export', 'npz']) == 0
    det = np.load(tmp_path / 'proc' / 'detections2d.npz')
    d = []
    for t in (0, 2, 3):
        for v, cam in enumerate(rig):
            uv = cv2_project(cam, X[t])
            inside = (uv >= -0.5).all(1) & (uv[:, 0] <= cam.width - 0.5) & \
                (uv[:, 1] <= cam.height - 0.5)
            dist = np.linalg.norm(det['points2d'][t, v] - uv, axis=-1)[inside]
            d += np.where(np.isfinite(dist), dist, np.inf).tolist()
    d = np.array(d)
    assert int(row['views_2d']) == len(d) > 100
    assert float(row['px_median']) == pytest.approx(np.median(d), rel=1e-9)
    assert float(row['pck2d@50px']) == pytest.approx(np.mean(d <= 50), abs=1e-12)
    capsys.readouterr()
    assert monet(args + ['--out', str(tmp_path / 'all'), '--include-labelled']) == 0
    assert 'scored instants: 4 of 4 (0-3)' in capsys.readouterr().out
    assert monet(args + ['--out', str(tmp_path / 'no'), '--reference-rate-mismatch',
                         'refuse']) == 2
    err = capsys.readouterr().err.strip()
    assert err.count('\n') == 0 and 'the reference is at 25 Hz, the recording at 30.3 Hz' in err


@pytest.mark.slow
def test_readme_eval_example_on_the_real_pose2sim_trc(shared_data, tmp_path, capsys):
    """The README's example: Pose2Sim's .trc (BODY_25B marker names) scored on the derived
    4-camera recording with `--keypoint-map body25b` alone (no 14 pairs by hand)."""
    trc = next((shared_data / 'pose2sim_demo_balancing').rglob('*.trc'))
    rec = shared_data / 'derived_pose2sim_4cam_mcap' / 'pose2sim_balancing_4cam'
    model = small_checkpoint(tmp_path / 'm.pt', seed=0, input_size=(64, 48))
    args = ['eval', str(model), '--data', str(rec), '--reference', str(trc),
            '--reference-axes', 'yzx', '--out', str(tmp_path / 'report')]
    assert monet(args) == 2
    assert 'map names with --keypoint-map' in capsys.readouterr().err
    assert monet(args + ['--keypoint-map', 'body25b']) == 0
    out = capsys.readouterr().out
    assert 'joints in 3D; 2D: its projection into the 4 cameras' in out
    assert 'not in the model: RBigToe, RSmallToe, RHeel, LBigToe, LSmallToe, LHeel, ' \
        'Nose)' in out
    assert 'reference time: rows matched to the nearest instant in time; 100 rows, 0 on ' \
        'no instant; 100 instants with a reference' in out
    assert 'scored instants: 100 of 100 (0-99)' in out
    with open(tmp_path / 'report' / 'reference.csv') as f:
        row = next(csv.DictReader(f))
    assert int(row['joints_3d']) >= 0.99 * 100 * 14 and row['points2d_from'] == 'projection'


def test_table_says_missed_for_an_infinite_median():
    """More misses than detections make the 2D median infinite (a miss is infinitely far):
    the printed table says so in words (reference.csv keeps inf, reference.json null)."""
    from monet_ros.commands.eval_reference import MISSED, table_cell

    assert table_cell(float('inf')) == MISSED
    assert table_cell(12.3456) == '12.3' and table_cell(0.5) == '0.5'
    assert table_cell(float('nan')) == 'nan' and table_cell(3) == '3'
