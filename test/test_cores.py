"""CPU cores shared out between workers (monet process --jobs, monet pipeline's detector
processes): the affinity mask counts, not the machine's cores."""
import shutil
import subprocess
import sys

import pytest

from monet_ros.cores import ViewThreads, cpu_model, threads_each, usable_cores, view_threads


@pytest.mark.parametrize('workers, cores, expected', [
    (1, 16, 16), (2, 16, 8), (3, 16, 5), (2, 2, 1), (3, 2, 1), (0, 4, 4)])
def test_threads_each_shares_the_cores_out_at_least_one_each(workers, cores, expected):
    assert threads_each(workers, cores) == expected


@pytest.mark.skipif(shutil.which('taskset') is None, reason='taskset (util-linux) missing')
def test_usable_cores_is_the_affinity_mask():
    code = 'from monet_ros.cores import threads_each, usable_cores; ' \
        'print(usable_cores(), threads_each(2))'
    out = subprocess.run(['taskset', '-c', '0', sys.executable, '-c', code],
                         capture_output=True, text=True, check=True).stdout.split()
    assert out == ['1', '1']


def test_view_threads_are_the_given_count_else_the_usable_cores():
    assert view_threads(3, cores=16) == 3
    assert view_threads(0, cores=16) == 16
    assert view_threads(0, cores=0) == 1
    assert view_threads(0) == usable_cores() == ViewThreads().threads


@pytest.mark.parametrize('threads', [1, 2, 3, 8])
def test_view_threads_run_every_view_once_and_reraise_an_error(threads):
    with ViewThreads(threads) as pool:
        for n in (0, 1, 5, 17):
            done = []
            pool.run(done.append, n)        # list.append is atomic
            assert sorted(done) == list(range(n))

        def work(i):
            if i == 4:
                raise ValueError('view 4')
        with pytest.raises(ValueError, match='view 4'):
            pool.run(work, 9)
        done = []
        pool.run(done.append, 6)            # still usable after an error
        assert sorted(done) == list(range(6))


def test_cpu_model_reads_the_model_name_line(tmp_path):
    info = tmp_path / 'cpuinfo'
    info.write_text('processor\t: 0\nvendor_id\t: GenuineIntel\n'
                    'model name\t: Intel(R) Xeon(R) Gold 6338 CPU @ 2.00GHz\nflags\t: fpu\n')
    assert cpu_model(info) == 'Intel(R) Xeon(R) Gold 6338 CPU @ 2.00GHz'
    missing = cpu_model(tmp_path / 'absent')          # not Linux: still a name, never raises
    assert isinstance(missing, str) and missing


def test_available_memory_reads_memavailable(tmp_path):
    from monet_ros.cores import available_memory
    info = tmp_path / 'meminfo'
    info.write_text('MemTotal:       24576000 kB\nMemFree:          512000 kB\n'
                    'MemAvailable:   16384000 kB\nBuffers:           1000 kB\n')
    assert available_memory(info) == 16384000 * 1024
    assert available_memory(tmp_path / 'absent') is None        # not Linux: unknown
    here = available_memory()
    assert here is None or here > 0
