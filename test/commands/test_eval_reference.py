"""`monet eval --reference`: one row per checkpoint, figures equal to an independent
scoring of `monet process`'s own 2D detections against the labels."""
import csv

from helpers.recordings import noise_recording, small_checkpoint
import numpy as np

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
