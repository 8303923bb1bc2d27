"""`monet process --precision int8` end to end on a small synthetic JPEG recording (coloured
blobs moving in front of a 4-camera ring, a small net trained to find them): the 3D is
float32's within a stated tolerance, and JPEG frames decoded at the crop's scale (the
default) give the 3D of full decodes; int8 is calibrated on the crops the run makes
(tracked or full frame), so either crop mode's 2D detections are float32's within a stated
tolerance, and each mode has its own cached quant."""
import shutil

from helpers.blob_net import NAMES, SIZE, train_blob_net
from helpers.blobs import blob_motion, render_blobs
from helpers.ring import ring_rig
import numpy as np
import pytest

from monet_ros.atomic import sha256_file
from monet_ros.cli import main as monet
from monet_ros.commands.process import ProcessConfig, process_recording
from monet_ros.crop_rule import TrackedRule, crop_boxes
from monet_ros.int8_calibration import int8_calibration, tracked_crops
from monet_ros.io import BagWriter, cloud_to_keypoints3d, open_bag
from monet_ros.models import Detector, save_checkpoint
from monet_ros.models.crop import crop_images
from monet_ros.models.quantize import cpu_int8_feature

T0 = 1_000_000_000_000_000_000
SIDE = 256          # frames 4x the 64 px network input: decoded at 1/4
TRACKED = 'tracked-m0.3-t4-k3'   # the crops key of the tracked rule's defaults


def jpeg_blob_recording(path, frames=8):
    """4 cameras, JPEG CompressedImage + camera_info + /tf_static; returns (rig, X (T, 3, 3))."""
    rig = ring_rig(4, width=SIDE, height=SIDE, focal=290.0, radius=3.0)
    X = blob_motion(frames, len(NAMES), seed=2)
    views = render_blobs(rig, X, radius_px=10.0)
    with BagWriter(path) as writer:
        writer.write_tf_static(T0, rig)
        for t in range(frames):
            stamp = T0 + t * 33_000_000
            for cam, images in zip(rig, views):
                writer.write_compressed_image(f'/{cam.name}/image_raw/compressed', stamp,
                                              images[t], f'{cam.name}_optical', quality=90)
                writer.write_camera_info(f'/{cam.name}/camera_info', stamp, cam,
                                         f'{cam.name}_optical')
    return rig, X


def points3d(out):
    return np.stack([cloud_to_keypoints3d(m.msg, units='m')['X']
                     for m in open_bag(out).messages(['/monet/keypoints3d'])])


needs_int8 = pytest.mark.skipif(cpu_int8_feature() is None,
                                reason='no VNNI / AMX-INT8 on this CPU')


@pytest.fixture(scope='module')
def scene(tmp_path_factory):
    """(recording folder, (rig, X), trained checkpoint): each test copies the checkpoint
    into its own folder, so the quants cached beside it are that test's."""
    root = tmp_path_factory.mktemp('int8')
    truth = jpeg_blob_recording(root / 'rec')
    model = root / 'blobs.pt'
    save_checkpoint(model, train_blob_net(), {'keypoints': NAMES})
    return root / 'rec', truth, model


@needs_int8
def test_int8_3d_is_float32s_and_reduced_decode_is_full_decodes(scene, tmp_path, capsys):
    rec, (rig, X), source = scene
    model = shutil.copy(source, tmp_path / 'blobs.pt')
    common = ['process', str(rec), '--model', str(model), '--no-track',
              '--quiet', '--backend', 'onnxruntime', '--threads', '1', '--export', 'none']
    assert monet(common + ['--out', str(tmp_path / 'f32'), '--precision', 'float32']) == 0
    assert monet(common + ['--out', str(tmp_path / 'int8'), '--precision', 'int8']) == 0
    out = capsys.readouterr().out
    assert 'monet process: precision int8' in out and '8 frames (32 views' in out
    # calibrated on the recording's full-frame crops (--no-track)
    assert [p.name.split('.')[2] for p in tmp_path.glob('blobs.*.int8.onnx')] == ['full']
    # auto does not pick int8 even with the quant cached (measured slower than float32)
    assert monet(common + ['--out', str(tmp_path / 'auto')]) == 0
    assert 'precision auto: float32 (backend onnxruntime; int8 only when asked' in \
        capsys.readouterr().out
    full = tmp_path / 'full'
    process_recording(rec, model, full, config=ProcessConfig(track=False),
                      device='cpu', progress=False, backend='onnxruntime', threads=1,
                      precision='float32', reduced_decode=False)
    f32, int8, whole = points3d(tmp_path / 'f32'), points3d(tmp_path / 'int8'), points3d(full)
    # float32 finds the blobs (else the comparisons say nothing): truth is X
    assert np.all(np.isfinite(f32))
    err_f32 = 1e3 * np.linalg.norm(f32 - X, axis=-1)
    err_int8 = 1e3 * np.linalg.norm(int8 - f32, axis=-1)
    err_decode = 1e3 * np.linalg.norm(f32 - whole, axis=-1)
    # measured: float32 vs truth median 16 mm (the net's 2D error); int8 vs float32 median
    # 0.9, largest 1.6 mm; reduced vs full decode median 1.0 mm, 23 of 24 points under 2 mm
    # and one at 12 mm, on the blob the net finds worst (28 mm from the truth): a net's
    # uncertain peak moves most with the small image change of a scaled IDCT (1 full-frame
    # px is ~10 mm here: focal 290 px at 3 m)
    assert np.median(err_f32) < 30.0
    assert err_int8.max() < 5.0
    assert np.median(err_decode) < 2.0 and np.percentile(err_decode, 90) < 5.0
    assert err_decode.max() < 20.0
    err_whole = 1e3 * np.linalg.norm(whole - X, axis=-1)
    assert abs(np.median(err_f32) - np.median(err_whole)) < 0.1 * np.median(err_whole)


def detections2d(out):
    return np.load(out / 'detections2d.npz')['points2d']          # (T, V, C, 2) source px


@needs_int8
def test_int8_calibrates_on_the_crops_of_the_run_tracked_or_full_frame(scene, tmp_path):
    rec, (rig, X), source = scene
    model = shutil.copy(source, tmp_path / 'blobs.pt')
    common = ['process', str(rec), '--model', str(model), '--quiet', '--backend',
              'onnxruntime', '--threads', '1', '--export', 'npz']
    points = {}
    for mode, flags in (('tracked', []), ('full', ['--no-track'])):
        for precision in ('float32', 'int8'):
            out = tmp_path / f'{mode}-{precision}'
            assert monet(common + flags + ['--out', str(out), '--precision', precision]) == 0
            points[mode, precision] = detections2d(out)
    # each crop mode its own quant, keyed by the checkpoint's sha256 and the crops
    sha = sha256_file(model)[:16]
    assert sorted(p.name for p in tmp_path.glob('*.int8.onnx')) == [
        f'blobs.{sha}.full.int8.onnx', f'blobs.{sha}.tracked-m0.3-t4-k3.int8.onnx']
    # float32 finds the blobs in both modes (else the comparison says nothing): the truth
    # is the projection of X; tracked crops zoom in (1 crop px is ~1.6 frame px here)
    truth = np.stack([np.stack([cam.project(x) for cam in rig]) for x in X])   # (T, V, C, 2)
    for mode in ('tracked', 'full'):
        assert np.all(np.isfinite(points[mode, 'float32'])), mode
        assert np.median(np.linalg.norm(points[mode, 'float32'] - truth, axis=-1)) < 3.0
    # measured (frame px, 256 x 256 frames): int8 vs float32 tracked median 0.08, largest
    # 0.57; full frame median 0.09, largest 0.80. The quant of the other mode is worse:
    # the full-frame quant run on tracked crops (the rule before) gives median 5.5,
    # largest 9.8
    for mode in ('tracked', 'full'):
        shift = np.linalg.norm(points[mode, 'int8'] - points[mode, 'float32'], axis=-1)
        assert np.all(np.isfinite(shift)), mode
        assert np.median(shift) < 0.5 and shift.max() < 2.0, (mode, shift)


def test_tracked_calibration_crops_are_the_tracked_rules_around_the_subject(scene):
    """int8_calibration.tracked_crops (the calibration set of tracked runs) against the
    crop rule applied to the true 3D: the float32 net's fused 3D is within a few mm of it,
    so the crops are the same to within JPEG noise, and far from full-frame crops."""
    rec, (rig, X), model = scene
    detector = Detector.from_checkpoint(model, device='cpu')
    # the rule's settings are the run's: here without trimming (3 blobs: the robust trim
    # may leave one out and fall back to the full frame, on either side of its threshold
    # for 3D a few mm apart)
    rule = TrackedRule(trim=0.0, margin=0.4)
    crops = tracked_crops(rec, detector, rule)                  # (T * V, 64, 64, 3)
    assert crops.shape == (len(X) * len(rig), SIZE, SIZE, 3) and crops.dtype == np.uint8
    frames = render_blobs(rig, X, radius_px=10.0)               # (V) of (T, H, W, 3)
    images = [frames[v][t] for t in range(len(X)) for v in range(len(rig))]
    boxes = [detector.boxes_for(rig, crop_boxes(rig, x, margin=0.4, trim=0.0)) for x in X]
    full = [detector.boxes_for(rig) for _ in X]
    expected = crop_images(images, np.concatenate(boxes), (SIZE, SIZE))
    whole = crop_images(images, np.concatenate(full), (SIZE, SIZE))
    diff = np.abs(crops.astype(float) - expected).mean(axis=(1, 2, 3))
    away = np.abs(crops.astype(float) - whole).mean(axis=(1, 2, 3))
    # measured: mean absolute difference per crop (grey levels) median 0.87, largest 1.2
    # (JPEG and a few mm of 3D); against full-frame crops at least 8.6
    assert diff.max() < 2.0 and away.min() > 5.0, (diff, away)


@needs_int8
def test_tracked_calibration_without_a_rig_is_one_line_exit_2(scene, tmp_path, capsys):
    rec, _, source = scene
    model = shutil.copy(source, tmp_path / 'blobs.pt')
    bare = tmp_path / 'bare'
    with BagWriter(bare) as writer:          # images only: no camera_info, no /tf_static
        writer.write_image('/cam0/image_raw', T0, np.zeros((64, 64, 3), np.uint8), 'cam0')
    argv = ['process', str(rec), '--model', str(model), '--quiet', '--backend',
            'onnxruntime', '--precision', 'int8', '--calibration', str(bare), '--out',
            str(tmp_path / 'out')]
    assert monet(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f'calibration {bare}: tracked crops need' in err[0], err
    assert not list(tmp_path.glob('*.int8.onnx')) and not (tmp_path / 'out').exists()
    # full-frame crops need no rig: --no-track calibrates on the same recording
    assert monet(argv + ['--no-track']) == 0
    assert [p.name.split('.')[2] for p in tmp_path.glob('*.int8.onnx')] == ['full']


def test_untracked_calibration_crops_are_the_runs_full_frame_or_fixed_box(scene):
    """int8_calibration for an untracked run: full frames (read by models.quantize) or,
    with a fixed box, that box grown to the input's aspect, as Detector.boxes_for crops."""
    rec, (rig, X), model = scene
    detector = Detector.from_checkpoint(model, device='cpu')
    frames = render_blobs(rig, X, radius_px=10.0)
    images = [frames[v][t] for t in range(len(X)) for v in range(len(rig))]
    assert int8_calibration(str(rec), False) == ('full', str(rec))
    box = (60.0, 50.0, 200.0, 170.0)
    key, make = int8_calibration(str(rec), False, box=box)
    assert key == 'box-60_50_200_170'
    crops = make(detector)
    boxes = np.concatenate([detector.boxes_for(rig, [box] * len(rig)) for _ in X])
    expected = crop_images(images, boxes, (SIZE, SIZE))
    diff = np.abs(crops.astype(float) - expected).mean(axis=(1, 2, 3))
    assert crops.shape == expected.shape and diff.max() < 2.0, diff      # JPEG noise


@needs_int8
def test_calibration_is_checked_cached_quant_or_not_and_the_quant_used_is_said(
        scene, tmp_path, capsys):
    """--calibration is refused the same (one line naming it and the file, exit 2, nothing
    written) whether or not a quant is cached; the first int8 run says what it calibrated
    on and which quant it wrote, later runs which cached quant they use (stderr)."""
    rec, _, source = scene
    cached, bare = tmp_path / 'cached', tmp_path / 'bare'
    cached.mkdir()
    bare.mkdir()
    model = shutil.copy(source, cached / 'blobs.pt')
    shutil.copy(source, bare / 'blobs.pt')
    sha = sha256_file(model)[:16]
    full, tracked = (cached / f'blobs.{sha}.{key}.int8.onnx' for key in ('full', TRACKED))

    def run(folder, flags):
        out = tmp_path / 'out'
        code = monet(['process', str(rec), '--model', str(folder / 'blobs.pt'), '--quiet',
                      '--backend', 'onnxruntime', '--precision', 'int8', '--threads', '1',
                      '--export', 'none', '--out', str(out)] + flags)
        written = out.exists()
        shutil.rmtree(out, ignore_errors=True)
        captured = capsys.readouterr()
        return code, captured.err.strip().splitlines(), written

    # first runs calibrate (full frame, then tracked) and say so; then the cache is said
    for flags, quant, crops in (([], tracked, TRACKED), (['--no-track'], full, 'full')):
        code, err, _ = run(cached, flags)
        said = [line for line in err if 'precision int8' in line]
        # 8 instants x 4 views: every crop of the recording (at most 64 are taken)
        assert code == 0 and said == [f'monet process: precision int8: calibrated on 32 '
                                      f'crops ({crops}) of {rec}; wrote {quant}'], err
        code, err, _ = run(cached, flags)
        said = [line for line in err if 'precision int8' in line]
        assert code == 0 and said == [f'monet process: precision int8: cached quant {quant} '
                                      f'(crops {crops}; not calibrating)'], err
    assert sorted(cached.glob('*.int8.onnx')) == [full, tracked]
    other = cached / f'blobs.0123456789abcdef.{TRACKED}.int8.onnx'
    other.write_bytes(tracked.read_bytes())         # named for other weights
    refused = (
        ([], tmp_path / 'nonexist', 'no such file or folder'),
        ([], full, 'a quant calibrated on other crops'),
        (['--no-track'], tracked, 'a quant calibrated on other crops'),
        ([], other, 'a quant of other weights'),
        ([], model, 'neither a recording (rosbag2 folder or .mcap) nor a quant'),
        (['--no-track'], model, 'neither a recording (rosbag2 folder or .mcap) nor a quant'),
    )
    for flags, calibration, why in refused:
        lines = {}
        for folder in (cached, bare):
            code, err, written = run(folder, flags + ['--calibration', str(calibration)])
            assert code == 2 and len(err) == 1 and not written, (folder, calibration, err)
            assert f'calibration {calibration}: ' in err[0] and why in err[0], err
            lines[folder] = err[0]
        assert lines[cached] == lines[bare]             # the same refusal, cached or not
    assert not list(bare.glob('*.int8.onnx'))
    assert sorted(cached.glob('*.int8.onnx')) == sorted([full, tracked, other])


@pytest.mark.parametrize('precision', ['float32', 'auto'])
def test_calibration_without_int8_is_one_line_exit_2(scene, tmp_path, capsys, precision):
    """--calibration is int8's calibration data: with another precision it was ignored
    without a word (nothing calibrated on it, nothing said); now refused in one line naming
    the option, before any output, by `monet process` and `monet pipeline` alike."""
    rec, _, model = scene
    for argv in (['process', str(rec), '--model', str(model), '--quiet',
                  '--out', str(tmp_path / 'out')],
                 ['pipeline', '--bag', str(rec), '--model', str(model), '--quiet',
                  '--lockstep']):
        assert monet(argv + ['--precision', precision, '--calibration', str(rec)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and '--calibration' in err[0] and 'int8' in err[0], err
        assert not (tmp_path / 'out').exists()
