"""bench/subjects_live.py on a few frames (4 cameras, no noise): the table's rows (1
subject; 2 and 3 with rival_peaks off and on); one subject, and 2 and 3 with rival_peaks,
are found with one identity each and exact 3D from the perfect heatmaps. Its discovery
maps are the detector node's discovery crop slots (the tiles by default)."""
import importlib.util

from helpers.detector_crops import expected_box, expected_K
import numpy as np
import pytest


@pytest.fixture
def bench(repo_root, monkeypatch):
    monkeypatch.syspath_prepend(str(repo_root / 'bench'))
    spec = importlib.util.spec_from_file_location(
        'bench_subjects_live', repo_root / 'bench' / 'subjects_live.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_live_bench_runs_and_finds_every_subject(bench, capsys):
    bench.main(['--frames', '6', '--cameras', '4', '--noise', '0'])
    rows = [line.split('|')[1:-1] for line in capsys.readouterr().out.splitlines()
            if line.startswith('| ') and line[2].isdigit()]
    assert [(r[0].strip(), r[1].strip()) for r in rows] == [
        ('1', 'off'), ('2', 'off'), ('2', 'on'), ('3', 'off'), ('3', 'on')]
    # one subject, and several with rival_peaks: every subject with one identity, exact
    # (mm; without rival_peaks a hidden joint takes the neighbour's peak: not exact)
    for row in [rows[0], rows[2], rows[4]]:
        assert row[3].strip() == '0' and row[4].strip() == '1.000', row   # IDSW, IDF1
        assert all(float(e) < 0.1 for e in row[5].split(',')), row


@pytest.mark.parametrize('tiles', [2, 0])
def test_the_live_bench_discovery_maps_are_the_detector_nodes_slots(bench, tiles):
    # what the detector node publishes before any subject is tracked (nodes/detector.py,
    # discovery_tiles 2 by default; test/nodes/test_subjects_live.py checks the node
    # against the same tiles): per view, no subject crop and the discovery slots N.. : a
    # 640x480 frame goes into the bench's 256 x 192 (H x W) network shrunk 640 / 192 = 3.3
    # > 2 times, so with discovery_tiles 2 it is 6 square tiles of 480 / 1.5 = 320 px at
    # steps of 160 (x fastest), each grown to the network's aspect 192 / 256; with 0 one
    # map of the whole frame padded to that aspect. Each a 48 x 64 map (the network's
    # heatmap grid) whose K is the tile's virtual camera, a visible keypoint's Gaussian
    # peak where that camera projects it. Fails before (the bench had no published_slots /
    # frame_maps): it rendered one whole-frame map of a 64 x 48 grid (not padded) per view
    # whatever the node published.
    from monet_ros.crop_rule import TrackedSubjects
    from monet_ros.synth.rig import RigConfig, make_rig

    cameras = make_rig(RigConfig(num_cameras=2), seed=0)
    assert all((c.width, c.height) == (640, 480) for c in cameras)
    N, C = 2, 14
    boxes = TrackedSubjects(units='m').boxes(cameras, 0, N)
    detector = bench.bench_detector([f'k{c}' for c in range(C)])
    if tiles:
        edges = [(x, y, x + 320, y + 320) for y in (0, 160) for x in (0, 160, 320)]
    else:
        edges = [(0, 0, 640, 480)]
    expected = [expected_box(e, 192 / 256) for e in edges]
    slots = bench.published_slots(detector, cameras, boxes, tiles)
    assert [(v, k) for v, k, _ in slots] == [(v, N + j) for v in range(2)
                                             for j in range(len(edges))]
    for _, k, box in slots:
        np.testing.assert_allclose(box, expected[k - N], atol=1e-9)

    # one keypoint per view near the image centre, visible, of one subject
    rng = np.random.default_rng(0)
    uv = np.stack([rng.uniform([250, 190], [390, 290], (1, C, 2)) for _ in cameras])
    visible = np.ones((2, 1, C), bool)
    present, sub, full = bench.frame_maps(detector, cameras, boxes, tiles, uv, visible)
    assert present == [0, 1] and sub == []
    assert [f[0] for f in full] == [v for v in range(2) for _ in edges]
    for n, (v, heat, K) in enumerate(full):
        box = np.array(expected[n % len(edges)])
        K_expected = expected_K(cameras[v].K, box, 48, 64)
        np.testing.assert_allclose(K, K_expected, atol=1e-9)
        assert heat.shape == (C, 64, 48) and heat.dtype == np.float32
        scale = np.array([48 / (box[2] - box[0]), 64 / (box[3] - box[1])])
        p = (uv[v, 0] - box[:2] + 0.5) * scale - 0.5                      # heatmap px (C, 2)
        inside = ((p >= 0) & (p <= [47, 63])).all(-1)
        assert inside.any()
        for c in np.flatnonzero(inside):
            y, x = np.unravel_index(np.argmax(heat[c]), heat[c].shape)
            assert abs(x - p[c, 0]) <= 0.5 and abs(y - p[c, 1]) <= 0.5, (n, c)
            assert heat[c].max() > 0.9 * np.exp(-1 / (2 * 1.5 ** 2))
