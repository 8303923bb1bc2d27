"""The demo's accuracy report: fused frames scored against the synthetic ground truth
(3D error, 2D PCK, left/right swaps), loop-shifted stamps mapped back."""
import numpy as np
import pytest

from monet_ros.commands.pipeline_demo import SYNTH_ARGS, TRAIN_ARGS, GroundTruthScore
from monet_ros.fusion import fuse_points
from monet_ros.geometry import load_rig, project_views
from monet_ros.skeleton import load_skeleton
from monet_ros.synth.recording import SynthConfig, synthesize


@pytest.fixture(scope='module')
def synth(tmp_path_factory):
    out = tmp_path_factory.mktemp('demo') / 'rec'
    synthesize(SynthConfig(cameras=3, frames=6, width=160, height=120, seed=3), out,
               progress=False)
    data = np.load(out / 'ground_truth.npz')
    return out, data['stamps'], data['keypoints3d'], load_rig(out / 'rig.yaml')


def fused(points3d, cameras, noise=0.0, seed=0):
    uv = project_views(cameras, points3d)                           # (V, C, 2)
    uv = uv + np.random.default_rng(seed).normal(scale=noise, size=uv.shape)
    return fuse_points(uv, np.ones(uv.shape[:2]), cameras)


def test_exact_detections_score_zero_error_full_pck_no_swap(synth):
    out, stamps, truth, cameras = synth
    score = GroundTruthScore(out / 'ground_truth.npz', out / 'rig.yaml')
    span = stamps[-1] - stamps[0] + (stamps[1] - stamps[0])
    for t, stamp in enumerate(stamps):
        score.on_fused(int(stamp) + 2 * span, fused(truth[t], cameras))   # third loop pass
    f = score.figures()
    assert f['frames'] == len(stamps)
    assert f['median_mm'] < 1e-3 and f['triangulated'] == 1.0
    assert f['pck2'] == 1.0 and f['swapped'] == 0.0
    assert 'left/right swapped 0%' in score.line()
    assert 'l_shoulder' in score.table()


def test_swapped_sides_and_noise_are_measured(synth):
    out, stamps, truth, cameras = synth
    names = list(load_skeleton('human14').keypoints)
    mirror = np.arange(len(names))
    for a, b in load_skeleton('human14').symmetric:
        mirror[names.index(a)], mirror[names.index(b)] = names.index(b), names.index(a)
    score = GroundTruthScore(out / 'ground_truth.npz', out / 'rig.yaml')
    for t, stamp in enumerate(stamps):
        score.on_fused(int(stamp), fused(truth[t][mirror], cameras, noise=3.0, seed=t))
    f = score.figures()
    assert f['swapped'] == 1.0
    # 3D error of the swapped joints: the distance between left and right, brute force
    pairs = [(names.index(a), names.index(b)) for a, b in load_skeleton('human14').symmetric]
    gap = np.linalg.norm(truth[:, [a for a, _ in pairs]] - truth[:, [b for _, b in pairs]],
                         axis=-1) * 1000
    assert f['keypoint_median_mm'][pairs[0][0]] == pytest.approx(
        np.median(gap[:, 0]), rel=0.2)
    assert score.instant(int(stamps[0]) - 5) is None
    score.on_fused(int(stamps[0]) + 1, fused(truth[0], cameras))     # no such instant
    assert score.unmatched == 1


def test_raw_and_filtered_keypoints_are_scored_apart(synth):
    """With the fusion node's live filter on, the listener gets the filtered keypoints too:
    both are scored (brute force here) and the line says which figure is which; with the
    filter off only the raw one."""
    out, stamps, truth, cameras = synth
    score = GroundTruthScore(out / 'ground_truth.npz', out / 'rig.yaml')
    offset = np.array([0.0, 0.03, 0.04])                    # a filter 50 mm off
    for t, stamp in enumerate(stamps):
        result = fused(truth[t], cameras, noise=2.0, seed=t)
        score.on_fused(int(stamp), result, truth[t] + offset)
    f = score.figures()
    raw = np.stack([np.linalg.norm(fused(truth[t], cameras, noise=2.0, seed=t).X - truth[t],
                                   axis=1) for t in range(len(stamps))]) * 1000
    assert f['median_mm'] == pytest.approx(np.median(raw))
    assert f['filtered_frames'] == len(stamps)
    assert f['filtered_median_mm'] == pytest.approx(50.0)
    assert f['filtered_mean_mm'] == pytest.approx(50.0)
    line = score.line()
    assert f'raw 3D error median {np.median(raw):.0f} mm' in line
    assert f'filtered (keypoints3d, {len(stamps)} frames) median 50 mm (mean 50)' in line
    plain = GroundTruthScore(out / 'ground_truth.npz', out / 'rig.yaml')
    plain.on_fused(int(stamps[0]), fused(truth[0], cameras))
    assert 'filtered' not in plain.line() and plain.figures()['filtered_frames'] == 0


def test_demo_recipe_is_sparse_distinct_sided_and_the_default_recipe_at_a_short_budget():
    assert '--distinct-sides' in SYNTH_ARGS
    fraction = float(SYNTH_ARGS[SYNTH_ARGS.index('--label-fraction') + 1])
    frames = int(SYNTH_ARGS[SYNTH_ARGS.index('--frames') + 1])
    assert 2 <= round(fraction * frames) <= 5
    # the default recipe (learning rate, schedule, augmentation) at 600 steps, where
    # supervised beats pseudo-labels (they pay from ~2000 steps: issue 22)
    assert TRAIN_ARGS[TRAIN_ARGS.index('--mode') + 1] == 'supervised'
    assert int(TRAIN_ARGS[TRAIN_ARGS.index('--steps') + 1]) < 2000
    assert '--lr' not in TRAIN_ARGS


def test_demo_training_shows_its_progress(tmp_path, repo_root):
    """The demo's `monet train` (its TRAIN_ARGS, a few steps here) shows a progress bar with
    the step count on stderr: the first `make demo` trains for minutes."""
    from helpers.blob_bag import write_blob_folder
    from helpers.blobs import blob_recording
    from helpers.commands import run_monet_process
    data = write_blob_folder(blob_recording(num_views=3, T=8, C=3, labelled=(2, 5)),
                             tmp_path / 'data')
    skeleton = tmp_path / 'blobs.yaml'
    skeleton.write_text('name: blobs\nkeypoints: [k0, k1, k2]\n')
    args = list(TRAIN_ARGS)
    args[args.index('--steps') + 1] = '3'
    args[args.index('--checkpoint-every') + 1] = '3'
    done = run_monet_process(repo_root, 'train', data, '--out', tmp_path / 'run', '--skeleton',
                             skeleton, '--width', '8', '--batch-labelled', '2', *args)
    assert done.returncode == 0, done.stderr
    assert 'train supervised: 100%' in done.stderr and '3/3' in done.stderr
