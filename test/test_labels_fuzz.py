"""Seeded bad-input sweep of the label readers and the validator: every outcome is a
right result or a LabelError naming the file (and line), never another exception."""
import numpy as np
import pandas as pd
import pytest

from monet_ros.labels import LabelError, LabelOptions, read_label_rows, resolve_labels
from monet_ros.labels_import import import_labels

STAMPS = 10**18 + np.arange(20, dtype=np.int64) * 33_333_333
CAMERAS = [('cam0', 64, 48), ('cam1', 64, 48)]
KP = ('a', 'b')
TOKENS = ['0', '-1', '19', '20', '1e400', 'nan', 'inf', '', ' ', 'x', 'cam0', 'cam1', 'a', 'b',
          '3.5', '63.5', '64', '-0.5', '1' + '0' * 30, str(STAMPS[3]), str(STAMPS[3] + 5),
          str(STAMPS[3] // 1_000_000), '"', ',', '\x00', 'é', '1,2']


def random_csv(rng, header):
    lines = [header]
    for _ in range(rng.integers(1, 6)):
        n = rng.integers(3, 7)
        lines.append(','.join(rng.choice(TOKENS, n)))
    return '\n'.join(lines) + '\n'


@pytest.mark.parametrize('seed', range(40))
def test_label_csv_sweep(tmp_path, seed):
    rng = np.random.default_rng(seed)
    header = rng.choice(['stamp_ns,camera,keypoint,u,v', 'frame,camera,keypoint,u,v',
                         'frame,cam,kp,u,v', ''])
    path = tmp_path / 'l.csv'
    path.write_text(random_csv(rng, header), encoding='utf-8')
    for skip in (False, True):
        try:
            rows = read_label_rows(path)
            labels, report = resolve_labels(rows, STAMPS, CAMERAS, KP,
                                            LabelOptions(skip_bad=skip))
        except LabelError as error:
            assert str(error).startswith(str(path)), error
            continue
        assert report.kept + report.total_skipped == report.rows == len(rows)
        assert labels.num_points == report.kept
        for views in labels.frames.values():          # what is kept lies in the image
            for pts in views.values():
                ok = np.isfinite(pts[:, 0])
                assert ((pts[ok] >= -0.5) & (pts[ok] <= [63.5, 47.5])).all()


@pytest.mark.parametrize('seed', range(20))
def test_dlc_csv_sweep(tmp_path, seed):
    rng = np.random.default_rng(seed)
    cols = pd.MultiIndex.from_product([['s'], list(KP), ['x', 'y']],
                                      names=['scorer', 'bodyparts', 'coords'])
    df = pd.DataFrame(rng.uniform(0, 60, (3, 4)), columns=cols,
                      index=[f'labeled-data/cam{i % 2}/img{i:03d}.png' for i in range(3)])
    df.to_csv(tmp_path / 'CollectedData_s.csv')
    lines = (tmp_path / 'CollectedData_s.csv').read_text().splitlines()
    i = rng.integers(len(lines))
    cells = lines[i].split(',')
    j = rng.integers(len(cells))
    cells[j] = str(rng.choice(TOKENS))
    if rng.random() < 0.3:
        cells = cells[:-1]
    lines[i] = ','.join(cells)
    (tmp_path / 'CollectedData_s.csv').write_text('\n'.join(lines) + '\n')
    try:
        result = import_labels('dlc', tmp_path / 'CollectedData_s.csv', cameras=('cam0', 'cam1'))
        resolve_labels(result.rows, STAMPS, CAMERAS, KP)
    except LabelError as error:
        assert str(tmp_path) in str(error), error


@pytest.mark.parametrize('fmt', ['dlc', 'sleap', 'anipose', 'dannce'])
def test_importers_refuse_files_of_other_kinds(tmp_path, fmt):
    import h5py
    junk = tmp_path / {'dlc': 'x.h5', 'sleap': 'x.h5', 'anipose': 'x.h5', 'dannce': 'x.mat'}[fmt]
    junk.write_bytes(b'\x89HDF\r\n\x1a\n' + bytes(100))
    with pytest.raises(LabelError, match=str(junk)):
        import_labels(fmt, junk)
    other = tmp_path / 'other.h5'
    with h5py.File(other, 'w') as f:
        f['tracks'] = np.zeros((2, 3))
        f['node_names'] = np.array([b'a'])
    if fmt != 'dannce':
        with pytest.raises(LabelError, match=str(other)):
            import_labels(fmt, other)
