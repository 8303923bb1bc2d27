"""`monet process REC... --jobs N`: several recordings in worker processes."""
from helpers.recordings import noise_recording, small_checkpoint
import numpy as np
import pytest

from monet_ros.cli import main as monet
from monet_ros.commands.process_many import output_folders, plan_jobs
from monet_ros.io import cloud_to_keypoints3d, open_bag


def keypoints3d(out):
    return [(m.stamp_ns, cloud_to_keypoints3d(m.msg, units='m'))
            for m in open_bag(out).messages(['/monet/keypoints3d'])]


@pytest.mark.slow
def test_two_jobs_equal_two_single_runs_and_a_failed_recording_is_reported(tmp_path, capsys):
    model = small_checkpoint(tmp_path / 'model.pt')
    recs = [tmp_path / 'a' / 'session', tmp_path / 'b' / 'session']   # same name: deduplicated
    noise_recording(recs[0], cameras=2, frames=3, seed=1)
    noise_recording(recs[1], cameras=2, frames=2, seed=2)
    common = ['--model', str(model), '--no-track', '--quiet', '--threads', '1']
    for i, rec in enumerate(recs):
        assert monet(['process', str(rec), '--out', str(tmp_path / f'single{i}')] + common) == 0
    capsys.readouterr()
    many = tmp_path / 'many'
    assert monet(['process', *map(str, recs), '--out', str(many), '--jobs', '2'] + common) == 0
    out = capsys.readouterr().out
    assert sorted(p.name for p in many.iterdir()) == ['session', 'session_2']
    for i, name in enumerate(('session', 'session_2')):
        single, multi = keypoints3d(tmp_path / f'single{i}'), keypoints3d(many / name)
        assert [s for s, _ in multi] == [s for s, _ in single] and len(single) == 3 - i
        for (_, a), (_, b) in zip(single, multi):
            for field in ('X', 'confidence', 'reprojection_error', 'num_views'):
                np.testing.assert_array_equal(b[field], a[field])
        assert (many / name / 'keypoints3d.csv').read_bytes() == \
            (tmp_path / f'single{i}' / 'keypoints3d.csv').read_bytes()
    rows = [line for line in out.splitlines() if line.startswith(f'monet process: {recs[0]} ')]
    assert len(rows) == 1 and rows[0].split()[4] == '3' and rows[0].endswith('ok')
    # each recording's summary after its name, as a run of it alone prints it
    for rec, name, frames in zip(recs, ('session', 'session_2'), (3, 2)):
        assert f'monet process: {rec}: {frames} frames (' in out, out
        assert f'monet process: {rec}: wrote csv: {many / name / "keypoints3d.csv"}' in out

    # A corrupt recording: one line naming it, the other still written, exit 2.
    corrupt = tmp_path / 'corrupt.mcap'
    corrupt.write_bytes(b'\x89MCAP0\r\n' + b'not a recording' * 10)
    again = tmp_path / 'again'
    assert monet(['process', str(corrupt), str(recs[0]), '--out', str(again), '--jobs', '2']
                 + common) == 2
    captured = capsys.readouterr()
    failed = [line for line in captured.err.splitlines() if 'failed' in line]
    assert len(failed) == 1 and failed[0].startswith(f'monet process: failed {corrupt}: ')
    assert 'Traceback' not in captured.err
    assert [p.name for p in again.iterdir()] == ['session']
    assert len(keypoints3d(again / 'session')) == 3
    row = [line for line in captured.out.splitlines() if str(corrupt) in line]
    assert len(row) == 1 and row[0].endswith('FAILED')
    assert '1 of 2 recordings processed' in captured.out and '1 failed' in captured.out


@pytest.mark.slow
def test_the_summary_says_which_folder_holds_which_recording(tmp_path, capfd):
    """Recordings of one name (dayA/recording, dayB/recording, ...) go to recording,
    recording_2, ...: the closing table names each one's folder, and that folder holds that
    recording's frames (told apart by their counts); no numpy warning reaches the terminal."""
    model = small_checkpoint(tmp_path / 'model.pt')
    frames = {'dayC': 2, 'dayA': 3, 'dayB': 4}
    recs = []
    for day, count in frames.items():
        recs.append(tmp_path / day / 'recording')
        noise_recording(recs[-1], cameras=2, frames=count, seed=count)
    many = tmp_path / 'many'
    assert monet(['process', *map(str, recs), '--out', str(many), '--jobs', '2', '--model',
                  str(model), '--quiet', '--threads', '1']) == 0
    captured = capfd.readouterr()        # the workers' stderr too (file descriptor 2)
    header = next(line for line in captured.out.splitlines()
                  if line.startswith('monet process: recording '))
    assert header.split()[2:4] == ['recording', 'output']
    for rec in recs:
        row, = [line for line in captured.out.splitlines()
                if line.startswith(f'monet process: {rec} ')]
        folder = row.split()[3]
        assert folder.startswith(str(many))
        assert len(keypoints3d(folder)) == frames[rec.parent.name], (row, folder)
    assert 'Warning' not in captured.err, captured.err


def test_jobs_get_one_gpu_each_round_robin_and_a_share_of_the_cores():
    bags = ['x/r1', 'y/r1', 'z/r2.mcap', 'w/r3']
    assert output_folders(bags, 'o') == ['o/r1', 'o/r1_2', 'o/r2', 'o/r3']
    jobs = plan_jobs(bags, 'o', jobs=2, cuda_devices=3, cores=16)
    assert [j.device for j in jobs] == ['cuda:0', 'cuda:1', 'cuda:2', 'cuda:0']
    assert {j.threads for j in jobs} == {8}
    cpu = plan_jobs(bags, 'o', jobs=3, cuda_devices=0, cores=2)
    assert [j.device for j in cpu] == [None] * 4 and {j.threads for j in cpu} == {1}
    assert {j.device for j in plan_jobs(bags, 'o', 2, device='cuda:1', cuda_devices=3)} == \
        {'cuda:1'}
    assert {j.threads for j in plan_jobs(bags[:1] * 2, 'o', 8, threads=3, cores=16)} == {3}
    assert {j.threads for j in plan_jobs(bags[:2], 'o', 8, cores=16)} == {8}


def test_bad_jobs_is_a_clear_error(tmp_path, capsys):
    model = small_checkpoint(tmp_path / 'model.pt')
    args = ['process', 'r1', 'r2', '--model', str(model), '--out', str(tmp_path / 'o')]
    assert monet(args + ['--jobs', '0']) == 2
    assert "'jobs': must be in 1..256, got 0" in capsys.readouterr().err


def children(pid):
    """The process ids of `pid`'s children (Linux /proc)."""
    from pathlib import Path
    found = []
    for task in Path(f'/proc/{pid}/task').glob('*'):
        try:
            found += [int(c) for c in (task / 'children').read_text().split()]
        except OSError:
            pass
    return found


def running(pid):
    """Whether process `pid` exists and is not a zombie (Linux /proc)."""
    from pathlib import Path
    try:
        return Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[0] != 'Z'
    except OSError:
        return False


@pytest.mark.slow
def test_sigterm_stops_every_worker_and_leaves_no_partial_output(tmp_path, repo_root):
    import os
    import signal
    import subprocess
    import sys
    import time

    model = small_checkpoint(tmp_path / 'model.pt')
    recs = [tmp_path / f'rec{i}' for i in range(2)]
    for i, rec in enumerate(recs):
        noise_recording(rec, cameras=2, frames=400, width=160, height=120, seed=i)
    out = tmp_path / 'out'
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join(filter(None, [str(repo_root), env.get('PYTHONPATH')]))
    proc = subprocess.Popen([sys.executable, '-m', 'monet_ros.cli', 'process', *map(str, recs),
                             '--model', str(model), '--out', str(out), '--jobs', '2',
                             '--quiet', '--no-track'], cwd=repo_root, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120          # both workers writing their output
        while len(list(out.glob('.*.partial'))) < 2 and proc.poll() is None and \
                time.monotonic() < deadline:
            time.sleep(0.1)
        assert proc.poll() is None and len(list(out.glob('.*.partial'))) == 2
        # the two workers (multiprocessing's resource tracker, also a child, ends when the
        # command's end closes its pipe)
        workers = [p for p in children(proc.pid)
                   if 'resource_tracker' not in open(f'/proc/{p}/cmdline').read()]
        assert len(workers) == 2, workers
        proc.send_signal(signal.SIGTERM)
        _, stderr = proc.communicate(timeout=120)
        # no worker outlives the command (gone, not left running or unreaped)
        assert [pid for pid in workers if running(pid)] == []
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, stderr
    assert 'monet process: stopped' in stderr and 'Traceback' not in stderr
    assert not out.exists()     # nothing half-written is left, nor the folder it made
