"""bench/real.py scores a model through `monet process`: its real-data path gives the 3D
that `monet process` writes (read back from the output bag here, independently)."""
import importlib.util

import numpy as np
import pytest
import torch

from monet_ros.cli import main as monet
from monet_ros.io import cloud_to_keypoints3d, open_bag
from monet_ros.io.export_tables import read_anipose_csv
from monet_ros.learning.config import TrainConfig
from monet_ros.learning.recording import load_recording
from monet_ros.learning.trainer import Trainer, TrainingData
from monet_ros.models import save_checkpoint


def bench_real(repo_root):
    spec = importlib.util.spec_from_file_location('bench_real', repo_root / 'bench' / 'real.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
def test_the_benchs_real_data_path_equals_monet_process(tmp_path, repo_root):
    torch.set_num_threads(1)
    data = tmp_path / 'synth'
    assert monet(['synth', '--out', str(data), '--frames', '8', '--cameras', '3', '--width',
                  '160', '--height', '120', '--label-fraction', '0.3', '--seed', '1',
                  '--quiet']) == 0
    recording = load_recording(data)
    config = TrainConfig(mode='supervised', architecture='small', input_size=64, width=8,
                         steps=30, batch_labelled=6, batch_pseudo=0, lr=3e-3, device='cpu')
    trainer = Trainer(config, TrainingData(recording, config, (64, 64), (16, 16)),
                      warn=lambda m: None)
    trainer.run(progress=False)
    checkpoint = tmp_path / 'model.pt'
    save_checkpoint(checkpoint, trainer.model, trainer.metadata())

    real = bench_real(repo_root)
    X, points, unmatched = real.process_path(data / 'recording', checkpoint, tmp_path / 'a',
                                             recording.stamps, recording.cameras)
    assert unmatched == 0 and X.shape == (recording.num_instants, 14, 3)
    assert points.shape == (recording.num_instants, 3, 14, 2)

    assert monet(['process', str(data / 'recording'), '--model', str(checkpoint), '--out',
                  str(tmp_path / 'b'), '--quiet']) == 0
    written = {m.msg.header.stamp.sec * 10 ** 9 + m.msg.header.stamp.nanosec:
               cloud_to_keypoints3d(m.msg, units='m')['X']
               for m in open_bag(tmp_path / 'b').messages('/monet/keypoints3d')}
    assert len(written) == recording.num_instants
    expected = np.stack([written[int(s)] for s in recording.stamps])
    finite = np.isfinite(expected)
    assert finite.any()                                   # something was triangulated
    np.testing.assert_array_equal(np.isfinite(X), finite)
    np.testing.assert_allclose(X[finite], expected[finite], atol=1e-6, rtol=0)

    # --filter optim: the bench's filtered scores are those of `monet process --filter optim`
    from monet_ros.temporal import FilterConfig
    X_f, _, _ = real.process_path(data / 'recording', checkpoint, tmp_path / 'c',
                                  recording.stamps, recording.cameras,
                                  filter_config=FilterConfig(method='optim'))
    assert monet(['process', str(data / 'recording'), '--model', str(checkpoint), '--out',
                  str(tmp_path / 'd'), '--filter', 'optim', '--export', 'csv', '--quiet']) == 0
    table = read_anipose_csv(tmp_path / 'd' / 'keypoints3d.csv')
    index = {int(s): n for n, s in enumerate(recording.stamps)}
    expected_f = np.full_like(X_f, np.nan)
    for row, stamp in enumerate(table['stamps_ns']):
        expected_f[index[int(stamp)]] = table['X'][row]
    finite = np.isfinite(expected_f)
    assert finite.any()
    np.testing.assert_array_equal(np.isfinite(X_f), finite)
    np.testing.assert_allclose(X_f[finite], expected_f[finite], atol=1e-6, rtol=0)


def test_modes_take_exact_controls_and_the_curve_pairs_them(repo_root, tmp_path):
    real = bench_real(repo_root)
    assert real.parse_arm('reprojection:lambda_r=0,lr=1e-3') == (
        'reprojection', {'lambda_r': 0, 'lr': 1e-3})
    assert real.arm_label('reprojection:lambda_r=0') == 'reprojection (lambda_r=0)'
    for bad in ('nonsense', 'reprojection:lambda_r', 'reprojection:no_field=1'):
        with pytest.raises(ValueError, match='--modes'):
            real.parse_arm(bad)
    arms = ['supervised', 'reprojection', 'reprojection:lambda_r=0']
    rows = []
    rng = np.random.default_rng(0)
    for seed in (0, 1, 2):
        for arm in arms:
            mean = float(rng.uniform(40, 90))
            rows.append({'labels': 3, 'seed': seed, 'mode': real.arm_label(arm),
                         'median_mm': mean - 5, 'mean_mm': mean, 'p90_mm': 2 * mean,
                         'pck10': 0.5})
    text = real.curve(rows, [3], [0, 1, 2], arms)
    by = {(r['seed'], r['mode']): r['mean_mm'] for r in rows}
    diffs = [by[(s, 'reprojection')] - by[(s, 'supervised')] for s in (0, 1, 2)]
    expect = ' / '.join(f'{d:+.0f}' for d in diffs) + f' | {sum(d < 0 for d in diffs)}/3'
    line = next(x for x in text.splitlines() if 'reprojection - supervised' in x)
    assert expect in line
    line = next(x for x in text.splitlines()
                if 'reprojection - reprojection (lambda_r=0)' in x)
    assert line.startswith('| 3 | ')
    mean_sup = np.mean([by[(s, 'supervised')] for s in (0, 1, 2)])
    assert '| 3 | supervised | 3 | ' in text and f'{mean_sup:.0f}' in text
    # every exact control is paired with its own arm, also where that arm has overrides
    arms = ['supervised', 'reprojection', 'reprojection:lambda_r=0',
            'reprojection_epipolar:lambda_e=5', 'reprojection_epipolar:lambda_e=0',
            'reprojection:distill_rounds=1', 'reprojection:distill_rounds=1,lambda_d=0']
    assert real.paired_arms(arms) == [
        ('reprojection', 'supervised'),
        ('reprojection', 'reprojection (lambda_r=0)'),
        ('reprojection_epipolar (lambda_e=5)', 'supervised'),
        ('reprojection_epipolar (lambda_e=5)', 'reprojection_epipolar (lambda_e=0)'),
        ('reprojection (distill_rounds=1)', 'supervised'),
        ('reprojection (distill_rounds=1)', 'reprojection (distill_rounds=1, lambda_d=0)')]
    rows = [{'labels': 3, 'seed': 0, 'mode': real.arm_label(arm), 'median_mm': 40.0,
             'mean_mm': 60.0 + k, 'p90_mm': 120.0, 'pck10': 0.5} for k, arm in enumerate(arms)]
    line = next(x for x in real.curve(rows, [3], [0], arms).splitlines()
                if 'reprojection_epipolar (lambda_e=5) - reprojection_epipolar (lambda_e=0)' in x)
    assert '| -1 | 1/1 |' in line                                   # 63 - 64 mm
    # the journal: a run written is a run skipped on the rerun
    job = (3, 'reprojection:lambda_r=0', 300.0, 2000, {'input_size': 128}, 1)
    journal = tmp_path / 'curve.runs.jsonl'
    journal.write_text(real.json.dumps({'key': real.job_key(job), 'row': rows[0]}) + '\n')
    assert real.read_journal(journal) == {real.job_key(job): rows[0]}
    assert real.job_key(job) != real.job_key((3, 'reprojection', 300.0, 2000,
                                              {'input_size': 128}, 1))
    # also scored with `monet process --filter optim`: another run; 'none' is the plain one
    assert real.job_key(job + ('none',)) == real.job_key(job)
    assert real.job_key(job + ('optim',)) != real.job_key(job)


def test_teacher_precision_scores_the_rounds_pseudo_labels_against_the_reference(tmp_path,
                                                                                 repo_root):
    """bench/real.py's teacher_precision (what a distillation round taught): a perfect
    teacher's pseudo-labels are the reference's projection (0 px, 0 mm); a teacher 10 mm off
    in x is 10 mm off, its pseudo-labels as far as the projections of the shifted points
    (brute force with Camera.project), and a point above the gate is not a pseudo-label."""
    from monet_ros.io.export_tables import write_anipose_csv
    data = tmp_path / 'synth'
    assert monet(['synth', '--out', str(data), '--frames', '6', '--cameras', '3', '--width',
                  '160', '--height', '120', '--seed', '1', '--quiet']) == 0
    rec = load_recording(data)
    real = bench_real(repo_root)
    gt = rec.gt3d
    T, C, _ = gt.shape
    reference2d = real.project_reference(gt, rec.cameras)
    config = TrainConfig()
    instants = np.array([1, 2, 4])
    names = list(rec.keypoints)

    def teacher(X, error):
        folder = tmp_path / f'round_{len(list(tmp_path.glob("round_*")))}'
        folder.mkdir()
        write_anipose_csv(folder / 'keypoints3d.csv', names, rec.stamps, X, error,
                          np.full((T, C), len(rec.cameras)), np.ones((T, C)))
        return real.teacher_precision(folder, config, rec, gt, reference2d, instants)

    perfect = teacher(gt, np.zeros((T, C)))
    assert perfect['pl_median_px'] < 1e-6 and perfect['pl_p90_px'] < 1e-6
    assert perfect['teacher_mean_mm'] < 1e-6 and perfect['teacher_kept_mean_mm'] < 1e-6
    inside = np.isfinite(reference2d[instants]).all(-1)
    assert perfect['pl_kept'] == inside.sum()

    shifted = gt + np.array([0.01, 0.0, 0.0])
    error = np.zeros((T, C))
    error[instants[0], 0] = config.distill_gate_px + 1          # above the gate
    got = teacher(shifted, error)
    assert got['teacher_mean_mm'] == pytest.approx(10.0)
    brute = []
    for t in instants:
        for v, cam in enumerate(rec.cameras):
            uv = cam.project(shifted[t])
            for c in range(C):
                if (t, c) != (instants[0], 0) and inside[list(instants).index(t), v, c]:
                    brute.append(np.linalg.norm(uv[c] - reference2d[t, v, c]))
    assert got['pl_kept'] == len(brute)
    assert got['pl_median_px'] == pytest.approx(np.median(brute), abs=1e-6)
    assert got['pl_p90_px'] == pytest.approx(np.percentile(brute, 90), abs=1e-6)
