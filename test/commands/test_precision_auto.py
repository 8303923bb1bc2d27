"""`--precision auto` (the default of monet train / process and the detector node's and
learner's `precision`): bfloat16 where this machine runs it natively, else float32, said in
one line naming the CPU feature. Checked against the CPU flags read independently from
/proc/cpuinfo (the flags oneDNN's bfloat16 paths need: avx512_bf16, amx_bf16)."""
from pathlib import Path

from helpers.blob_bag import write_blob_folder
from helpers.blobs import blob_recording
from helpers.commands import run_monet_process
import pytest

from monet_ros.models import build_model
from monet_ros.models.detector import Detector, resolve_precision

TRAIN = ['--architecture', 'small', '--input-size', '48', '--width', '16',
         '--batch-labelled', '2', '--batch-pseudo', '2', '--batch-unlabeled', '1',
         '--views-per-instant', '2', '--mode', 'supervised', '--device', 'cpu',
         '--threads', '1', '--no-progress']


def cpu_flags():
    text = Path('/proc/cpuinfo').read_text()
    return set(next(line for line in text.splitlines() if line.startswith('flags')).split())


def expected_line():
    """The choice and line auto must give on this machine's CPU, from its flags."""
    flags = cpu_flags()
    found = [name for flag, name in (('amx_bf16', 'AMX'), ('avx512_bf16', 'AVX512-BF16'))
             if flag in flags]
    if found:
        return 'bfloat16', f'precision auto: bfloat16 (cpu has {" and ".join(found)}: native)'
    return 'float32', ('precision auto: float32 (the CPU has neither AVX512-BF16 nor AMX, so '
                       'bfloat16 would be emulated)')


def expected_process_line():
    """monet process's line: its --backend auto follows the precision (models.detector.
    resolve_inference): torch for native bfloat16, ONNX Runtime for float32 on a CPU."""
    choice, line = expected_line()
    if choice == 'bfloat16':
        return f'{line}; backend auto: torch (bfloat16 is native on this CPU)'
    return (f'{line}; backend auto: onnxruntime (float32 on a CPU: faster than torch, '
            'bench/results/pipeline.md)')


pytestmark = pytest.mark.skipif(not Path('/proc/cpuinfo').is_file(),
                                reason='CPU flags are read from /proc/cpuinfo')


def monet(repo_root, *args):
    return run_monet_process(repo_root, *args)


def test_auto_is_bfloat16_exactly_where_the_cpu_has_it():
    choice, line = expected_line()
    assert resolve_precision('auto', 'torch', 'cpu') == (choice, line)
    # onnxruntime runs float32; explicit values are kept
    assert resolve_precision('auto', 'onnxruntime', 'cpu')[0] == 'float32'
    assert resolve_precision('float32', 'torch', 'cpu') == ('float32', 'precision float32')
    detector = Detector(build_model('small', 3, width=8), {'keypoints': ['a', 'b', 'c']},
                        device='cpu', precision='auto')
    assert (detector.precision, detector.precision_note) == (choice, line)


def test_train_and_process_default_to_auto_and_say_it_once(repo_root, tmp_path):
    choice, line = expected_line()
    rec = blob_recording(num_views=3, T=12, C=3, labelled=(2, 5))
    data = write_blob_folder(rec, tmp_path / 'data')
    skeleton = tmp_path / 'blobs.yaml'
    skeleton.write_text('name: blobs\nkeypoints: [k0, k1, k2]\n')
    done = monet(repo_root, 'train', data, '--out', tmp_path / 'run', '--skeleton', skeleton,
                 '--steps', 2, '--checkpoint-every', 2, *TRAIN)
    assert done.returncode == 0, done.stderr
    assert done.stderr.splitlines().count(f'monet train: {line}') == 1
    assert sum('precision' in x for x in done.stderr.splitlines()) == 1
    done = monet(repo_root, 'process', data / 'recording', '--model', tmp_path / 'run/model.pt',
                 '--rig', data / 'rig.yaml', '--skeleton', skeleton, '--out', tmp_path / 'out',
                 '--device', 'cpu', '--threads', '1', '--quiet', '--export', 'none')
    assert done.returncode == 0, done.stderr
    # process: on stdout (its stderr keeps one line for a bad input)
    assert done.stdout.splitlines().count(f'monet process: {expected_process_line()}') == 1, \
        done.stdout
    assert sum('precision' in x for x in (done.stdout + done.stderr).splitlines()) == 1
