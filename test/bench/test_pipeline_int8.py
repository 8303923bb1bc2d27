"""bench/pipeline.py --precision int8: quantised once, before the measured runs, the way
`monet pipeline --precision int8` does it (on the tracked crops of a recording of what the
bench's cameras send), and found cached by the next preparation; a precision the backend
cannot run is refused in one line before any run."""
import hashlib
import importlib.util
import subprocess
import sys

import numpy as np
import pytest

from monet_ros.io import any_image_to_numpy, open_bag
from monet_ros.models.quantize import CALIBRATION_IMAGES, cpu_int8_feature
from monet_ros.rig_select import load_node_rig
from monet_ros.synth.rig import RigConfig, make_rig

TRACKED = 'tracked-m0.3-t4-k3'     # the crops key of the default tracked rule


def bench_module(repo_root):
    spec = importlib.util.spec_from_file_location('bench_pipeline',
                                                  repo_root / 'bench' / 'pipeline.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_each_precision_gets_the_backend_that_runs_it(repo_root):
    bench = bench_module(repo_root)
    # as `monet pipeline`'s default --backend auto (onnxruntime is installed here)
    assert [bench.backend_for(p) for p in ('float32', 'bfloat16', 'int8')] == \
        ['onnxruntime', 'torch', 'onnxruntime']
    assert bench.backend_for('float32', 'torch') == 'torch'
    assert bench.backend_for('float32', 'onnxruntime') == 'onnxruntime'


def test_int8_on_torch_is_refused_in_one_line_before_any_run(repo_root):
    proc = subprocess.run([sys.executable, str(repo_root / 'bench' / 'pipeline.py'),
                           '--precision', 'float32', 'int8', '--backend', 'torch'],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip().splitlines()[-1] == (
        "pipeline.py: error: --precision int8 with --backend torch: precision int8 needs "
        "backend onnxruntime (ONNX Runtime static quantisation), got 'torch'")
    assert proc.stdout == ''                   # nothing measured


@pytest.mark.skipif(cpu_int8_feature() is None, reason='no VNNI / AMX-INT8 on this CPU')
def test_int8_is_calibrated_once_on_the_feed_and_found_cached(repo_root, tmp_path):
    bench = bench_module(repo_root)
    views = 2
    quant, note, _ = bench.prepare_int8_runs(tmp_path, views, threads=1, input_size=64)
    model = tmp_path / 'small64.pt'
    sha = hashlib.sha256(model.read_bytes()).hexdigest()
    expected = tmp_path / f'small64.{sha[:16]}.{TRACKED}.int8.onnx'
    recording = tmp_path / f'int8_calibration_{views}'
    # calibrated as `monet pipeline` calibrates, on the crops its detectors make (tracked)
    assert quant == str(expected) and expected.is_file()
    assert note == (f'precision int8: calibrated on {CALIBRATION_IMAGES} crops ({TRACKED}) '
                    f'of {recording}; wrote {expected}')
    assert sorted(p.name for p in tmp_path.glob('*.int8.onnx')) == [expected.name]
    # the recording is what the bench's cameras send: their rig and frames
    cameras, _ = load_node_rig(recording)
    rig = make_rig(RigConfig(num_cameras=views))
    assert [c.name for c in cameras] == [c.name for c in rig]
    np.testing.assert_allclose([c.K for c in cameras], [c.K for c in rig])
    first = {m.topic: any_image_to_numpy(m.msg)
             for m in open_bag(recording).messages([c.topic for c in rig])
             if m.stamp_ns == 1_767_225_600_000_000_000}
    frames = bench.feed_frames(views)[0]
    for v, cam in enumerate(rig):
        np.testing.assert_array_equal(first[cam.topic], frames[v])
    # the measured runs' preparation (and a user's second run) finds it and calibrates nothing
    written = expected.stat().st_mtime_ns
    again, note, _ = bench.prepare_int8_runs(tmp_path, views, threads=1, input_size=64)
    assert again == quant and expected.stat().st_mtime_ns == written
    assert note == f'precision int8: cached quant {expected} (crops {TRACKED}; not calibrating)'
