"""monet_ros.jit: kernels give the numbers of their uncompiled form, compile once per dtype
whatever the arrays' layout, and a later process loads the machine code from the cache."""
import os
from pathlib import Path
import subprocess
import sys

import numpy as np

from monet_ros.geometry.camera import _radial_undistort
from monet_ros.jit import kernel

ROOT = Path(__file__).resolve().parents[1]


@kernel
def _weighted_sum(x, w):
    out = 0.0
    for i in range(x.shape[0]):
        for j in range(x.shape[1]):
            out += w[i] * x[i, j]
    return out


def test_a_kernel_is_its_python_and_compiles_once_per_dtype():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(6, 8))
    w = rng.random(6)
    want = _weighted_sum.py_func(x, w)
    assert np.isclose(want, (w[:, None] * x).sum())               # the loops as written
    readonly = x.copy()
    readonly.setflags(write=False)
    for args in ((x, w), (readonly, w), (x[:, ::2].repeat(2, axis=1), w),
                 (np.asfortranarray(x), w[::-1].copy()[::-1])):
        assert _weighted_sum(*args) == _weighted_sum.py_func(*args)
    assert len(_weighted_sum.dispatcher.signatures) == 1
    assert x.flags.writeable and not readonly.flags.writeable      # inputs untouched


def test_a_later_process_loads_the_cached_machine_code(tmp_path):
    """Two processes undistort with a radial lens model (a kernel): the first compiles and
    writes numba's cache into NUMBA_CACHE_DIR, the second loads it (numba's cache debug
    lines say which) and gets the same points."""
    script = ('import numpy as np\n'
              'from monet_ros.geometry.camera import _radial_undistort\n'
              'uv = np.array([[[100.0, 50.0], [600.0, 400.0]]])\n'
              'K = np.array([[[800.0, 0, 320], [0, 800, 240], [0, 0, 1]]])\n'
              'print(repr(_radial_undistort(uv, K, np.array([[-0.2, 0.05, 0.0]]), 20, '
              '1e-15).tolist()))\n')
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path), NUMBA_DEBUG_CACHE='1',
               PYTHONPATH=str(ROOT))
    runs = [subprocess.run([sys.executable, '-c', script], env=env, capture_output=True,
                           text=True, timeout=300, cwd=tmp_path) for _ in range(2)]
    for run in runs:
        assert run.returncode == 0, run.stderr
    first, second = (run.stdout.splitlines() for run in runs)
    assert any(line.startswith('[cache] data saved') for line in first)
    assert any(line.startswith('[cache] data loaded') for line in second)
    assert not any(line.startswith('[cache] data saved') for line in second)
    assert first[-1] == second[-1]
    uv = np.array([[[100.0, 50.0], [600.0, 400.0]]])
    K = np.array([[[800.0, 0, 320], [0, 800, 240], [0, 0, 1]]])
    here = _radial_undistort(uv, K, np.array([[-0.2, 0.05, 0.0]]), 20, 1e-15)
    assert repr(here.tolist()) == first[-1]


def test_warm_up_compiles_what_the_first_frame_uses():
    """warm_up compiles every kernel of the imported modules from its example arguments,
    with the types the callers pass: a frame of two subjects (undistortion of a radial
    lens model, the association's pair costs and merging) then compiles nothing more."""
    from monet_ros.jit import _KERNELS, warm_up
    from monet_ros.skeleton import load_skeleton
    from monet_ros.subjects import associate
    from monet_ros.synth.rig import RigConfig, make_rig
    from monet_ros.synth.subjects import shuffled_instances, subjects_keypoints

    warm_up()
    examples = [k for k in _KERNELS if k.example is not None]
    names = {k.__name__ for k in examples}
    assert {'_radial_undistort', '_pair_costs', '_merge_clusters'} <= names
    assert all(len(k.dispatcher.signatures) == 1 for k in examples)
    cams = make_rig(RigConfig(num_cameras=4))
    assert any(c.dist.any() for c in cams)                          # a radial lens model
    X = subjects_keypoints(load_skeleton('human14'), 2, np.arange(2) / 30.0)
    points, _ = shuffled_instances(X, cams, noise_px=1.0, seed=0)
    assert len(associate(points[0], cams).X) == 2
    assert all(len(k.dispatcher.signatures) == 1 for k in examples)
