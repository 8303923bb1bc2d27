"""Generated sessions and references for `monet import videos` and `monet eval
--reference`'s loader: image folders with gaps (random missing files per camera), variable
frame rate videos (random container times), and 3D references at other rates (random
rate, length and start). Each case is a right result checked against what the generator
put in, a 'skipped and counted' one, or one clear error line."""
from dataclasses import dataclass

import cv2
from helpers.reliability import RELIABILITY, outcome, record
from helpers.ring import ring_rig
from helpers.videos import write_vfr_mp4
from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

from monet_ros.geometry import save_rig
from monet_ros.io import open_bag
from monet_ros.io.images import any_image_to_numpy

START = 1_800_000_000_000_000_000
FPS = 30.0


@pytest.fixture(scope='module')
def calibration(tmp_path_factory):
    path = tmp_path_factory.mktemp('cal') / 'rig.yaml'
    save_rig(path, ring_rig(3, width=32, height=24, focal=30.0))
    return path


def _stamp(i):
    return START + round(i * 1e9 / FPS)


def _summary_counts(stdout, label):
    """{camera: n} printed after `label` in the import summary ({} when not printed)."""
    import ast
    if label not in stdout:
        return {}
    return ast.literal_eval(stdout.split(label, 1)[1].split('}', 1)[0].strip() + '}')


@settings(RELIABILITY, max_examples=8)
@given(first=st.integers(0, 3), length=st.integers(2, 9),
       gaps=st.lists(st.sets(st.integers(0, 8), max_size=4), min_size=3, max_size=3),
       pattern=st.sampled_from(['frame_{:04d}.png', 'img{}.png', 'cam_x_{:06d}.jpg']))
def test_image_folders_with_gaps(tmp_path_factory, calibration, first, length, gaps,
                                 pattern):
    """Every written view is the file of its own number (pixels: flat grey = number); a
    missing file is a missing view at its instant, the counts printed equal the gaps."""
    root = tmp_path_factory.mktemp('gaps')
    present = {}
    for v, gap in enumerate(gaps):
        numbers = [first + k for k in range(length) if k not in gap]
        present[v] = numbers
        folder = root / f'cam{v}'
        folder.mkdir()
        for n in numbers:
            cv2.imwrite(str(folder / pattern.format(n)), np.full((24, 32, 3), 10 * n, np.uint8))
    base = min((min(p) for p in present.values() if p), default=None)
    argv = ['import', 'videos', root, '--calibration', calibration, '--out', root / 'rec',
            '--fps', '30', '--format', 'png', '--start-ns', START, '--quiet']

    def check(stdout, stderr):
        bag = open_bag(root / 'rec')
        last = max(max(p) for p in present.values() if p) - base
        for v, numbers in present.items():
            topic = f'/cam{v}/image_raw/compressed'
            got = {m.stamp_ns: any_image_to_numpy(m.msg) for m in bag.messages([topic])}
            assert sorted(got) == [_stamp(n - base) for n in numbers]
            for n in numbers:
                assert int(got[_stamp(n - base)][0, 0, 0]) == 10 * n
        written = {n - base for p in present.values() for n in p}
        expected = {f'cam{v}': len(written) - len(p) for v, p in present.items()
                    if len(written) - len(p)}
        assert _summary_counts(stdout, 'instants without a view (missing frames):') == expected
        assert f'x {len(written)} instants' in stdout and last + 1 >= len(written)
        return 'skipped and counted' if expected else 'right result'

    if any(not p for p in present.values()):               # a camera with no file at all
        outcome('import videos', argv, names=('cam', 'no image'), expect='clear error')
    else:
        outcome('import videos', argv, check=check)


@settings(RELIABILITY, max_examples=6)
@given(steps_ms=st.lists(st.integers(10, 90), min_size=3, max_size=14),
       fps=st.sampled_from([20.0, 25.0, 30.0, 50.0]))
def test_variable_frame_rate_videos(tmp_path_factory, calibration, steps_ms, fps):
    """A VFR MP4 (random container times) beside two image folders: each of its frames
    lands on the instant nearest its container time (at most half a period off), the
    nearer of two frames nearest one instant is kept, the rest counted; the video is named
    as VFR whenever its intervals differ."""
    root = tmp_path_factory.mktemp('vfr')
    times = np.concatenate([[0.0], np.cumsum(steps_ms)]) / 1000.0
    grey = np.stack([np.full((24, 32, 3), 16 * (j % 16), np.uint8) for j in range(len(times))])
    write_vfr_mp4(root / 'cam0.mp4', grey, times)
    # the times the container holds (ticks of its timescale), as OpenCV reads them
    cap = cv2.VideoCapture(str(root / 'cam0.mp4'))
    held = []
    while cap.read()[0]:
        held.append(cap.get(cv2.CAP_PROP_POS_MSEC))
    cap.release()
    np.testing.assert_allclose(held, times * 1000, atol=0.1)
    times = np.array(held) / 1000.0
    instants = np.array([round(ms * fps / 1000.0) for ms in held])
    for v in (1, 2):
        folder = root / f'cam{v}'
        folder.mkdir()
        for i in range(instants[-1] + 1):
            cv2.imwrite(str(folder / f'{i:04d}.png'), np.zeros((24, 32, 3), np.uint8))
    argv = ['import', 'videos', root, '--calibration', calibration, '--out', root / 'rec',
            '--fps', fps, '--raw', '--start-ns', START, '--quiet']

    def check(stdout, stderr):
        got = {m.stamp_ns: np.asarray(any_image_to_numpy(m.msg)) for m in
               open_bag(root / 'rec').messages(['/cam0/image_raw'])}
        keep = {}
        for i in np.unique(instants):
            js = np.flatnonzero(instants == i)
            keep[i] = js[np.argmin(np.abs(times[js] - i / fps))]
        assert sorted(got) == [START + round(i * 1e9 / fps) for i in sorted(keep)]
        for i, j in keep.items():
            stamp = START + round(i * 1e9 / fps)
            assert abs(float(got[stamp].mean()) - 16 * (j % 16)) < 6
            assert abs(stamp - START - times[j] * 1e9) <= 0.5e9 / fps + 1
        dropped = len(times) - len(keep)
        assert _summary_counts(stdout, 'frames dropped (a second frame nearest one instant):') \
            == ({'cam0': dropped} if dropped else {})
        ratio = max(steps_ms) / min(steps_ms)
        if not 1.05 < ratio < 1.15:          # clear of the 10 % rule's edge (tick rounding)
            assert ('cam0.mp4 has a variable frame rate' in stderr) == (ratio > 1.1)
        missing = instants[-1] + 1 - len(keep)
        return 'skipped and counted' if dropped or missing else 'right result'

    outcome('import videos', argv, check=check)


@dataclass
class Index:
    stamps: np.ndarray
    cameras: list


@settings(RELIABILITY, max_examples=12)
@given(ref_hz=st.sampled_from([20.0, 24.0, 25.0, 29.97, 30.0, 50.0, 60.0, 120.0]),
       rows=st.integers(2, 40), frames=st.integers(2, 20), policy=st.sampled_from(
           ['resample', 'refuse']), seed=st.integers(0, 2**31 - 1))
def test_references_at_other_rates(tmp_path_factory, ref_hz, rows, frames, policy, seed):
    """A TRC at ref_hz on a 30 Hz recording: at the same rate (within 2 %: 29.97) each
    instant takes the row nearest in time; otherwise linear interpolation in time (equal
    to np.interp) or, with 'refuse', a LabelError naming both rates; rows outside the
    recording are counted; a reference wholly outside is an error naming the file."""
    from monet_ros.evaluation.reference import load_reference
    from monet_ros.io.export_tables import write_trc
    from monet_ros.labels import LabelError

    rng = np.random.default_rng(seed)
    path = tmp_path_factory.mktemp('ref') / 'ref.trc'
    t_ref = np.arange(rows) / ref_hz
    X_ref = rng.normal(size=(rows, 2, 3))
    write_trc(path, ('a', 'b'), 10**18 + np.round(t_ref * 1e9).astype(np.int64), X_ref)
    stamps = START + np.round(np.arange(frames) * 1e9 / FPS).astype(np.int64)
    index = Index(stamps, ring_rig(2, width=32, height=24, focal=30.0))
    t_rec = (stamps - stamps[0]) / 1e9
    same = abs(ref_hz - FPS) <= 0.02 * FPS
    try:
        ref = load_reference(path, index, ('a', 'b'), rate_policy=policy)
    except LabelError as error:
        assert policy == 'refuse' and not same, error
        assert f'ref.trc: the reference is at {ref_hz:.4g} Hz, the recording at 30 Hz' in \
            str(error)
        record('load_reference', 'clear error')
        return
    assert policy == 'resample' or same
    half = 0.5 / FPS
    outside = int(((t_ref < -half) | (t_ref > t_rec[-1] + half)).sum())
    if same:
        j = np.abs(t_ref[None] - t_rec[:, None]).argmin(1)
        near = np.abs(t_ref[j] - t_rec) <= half
        expected = np.where(near[:, None, None], X_ref[j], np.nan)
        assert ref.alignment['rule'] == 'nearest'
    else:
        expected = np.stack([[[np.interp(t, t_ref, X_ref[:, c, d], left=np.nan,
                                         right=np.nan) for d in range(3)] for c in range(2)]
                             for t in t_rec])
        assert ref.alignment['rule'] == 'linear'
        assert ref.alignment['rows_unmatched'] == outside
    np.testing.assert_allclose(ref.X, expected, rtol=1e-9, atol=1e-9)
    record('load_reference', 'skipped and counted' if ref.alignment['rows_unmatched']
           else 'right result')
