"""A node that cannot start says why in ONE line on stderr and exits 2 (issue 25 item 15),
even when the library's text spans lines: torch's refusal of a checkpoint that pickles a
numpy array is 4+ lines with terminal styling. The real executables, started as a user
would (`model:=` a bad checkpoint; a learner resuming from one)."""
from helpers.ros import NodeProcess
from helpers.scenes import ring_rig
import numpy as np
import torch

from monet_ros.geometry import save_rig


def bad_checkpoint(path):
    """A torch.save file that weights_only loading refuses with a multi-line message."""
    torch.save({'format': 'monet_ros.checkpoint/1', 'weights': np.arange(3)}, path)
    with open(path, 'rb') as stream:
        try:
            torch.load(stream, weights_only=True)
        except Exception as error:  # noqa: BLE001 - the text is what matters here
            assert str(error).count('\n') >= 3       # the premise: torch's text spans lines
    return path


def assert_one_line_exit_2(node, name, path):
    assert node.wait(timeout=120) == 2, node.output()
    lines = [line for line in node.stderr_path.read_text().splitlines() if line.strip()]
    assert len(lines) == 1, node.output()
    # a pickle is refused as unsafe, without relaying torch's advice to load it anyway
    assert lines[0].startswith(f'{name}: error: {path}: not a monet checkpoint'), lines
    assert 'unsafe' in lines[0] and 'weights_only=False' not in lines[0], lines
    assert '\x1b' not in lines[0]
    assert 'Traceback' not in node.output()


def test_detector_with_a_bad_checkpoint_prints_one_line(ros_env, tmp_path):
    save_rig(tmp_path / 'rig.yaml', ring_rig(2))
    model = bad_checkpoint(tmp_path / 'bad.pt')
    params = dict(rig=str(tmp_path / 'rig.yaml'), model=str(model), device='cpu')
    with NodeProcess('detector', ros_env, params) as node:
        assert_one_line_exit_2(node, 'detector', model)


def test_learner_resuming_from_a_bad_checkpoint_prints_one_line(ros_env, tmp_path):
    out = tmp_path / 'run'
    out.mkdir()
    (out / 'trainer_state.pt').write_bytes(b'')     # a run to resume: its model is bad
    model = bad_checkpoint(out / 'model.pt')
    params = dict(bags=[str(tmp_path / 'no_bag_needed')], out=str(out), resume=True)
    with NodeProcess('learner', ros_env, params) as node:
        assert_one_line_exit_2(node, 'learner', model)


def test_detector_int8_without_calibration_names_the_parameter(ros_env, tmp_path):
    from helpers.recordings import small_checkpoint

    from monet_ros.models.quantize import cpu_int8_feature
    save_rig(tmp_path / 'rig.yaml', ring_rig(2))
    model = small_checkpoint(tmp_path / 'model.pt')
    params = dict(rig=str(tmp_path / 'rig.yaml'), model=str(model), device='cpu',
                  backend='onnxruntime', precision='int8')
    with NodeProcess('detector', ros_env, params) as node:
        assert node.wait(timeout=120) == 2, node.output()
    lines = [line for line in node.stderr_path.read_text().splitlines() if line.strip()]
    assert len(lines) == 1, node.output()
    if cpu_int8_feature() is None:                    # refused for the CPU first
        assert 'needs a CPU with AVX512-VNNI' in lines[0], lines
    else:
        assert 'precision int8 needs calibration data' in lines[0], lines
        assert 'parameter calibration' in lines[0] and 'model.' in lines[0], lines
    assert 'Traceback' not in node.output()


def test_detector_calibration_without_int8_names_the_parameter(ros_env, tmp_path):
    """`calibration` is int8's calibration data: with another precision nothing uses it,
    and the node started without a word; refused like `monet process --calibration`."""
    from helpers.recordings import small_checkpoint
    save_rig(tmp_path / 'rig.yaml', ring_rig(2))
    model = small_checkpoint(tmp_path / 'model.pt')
    params = dict(rig=str(tmp_path / 'rig.yaml'), model=str(model), device='cpu',
                  precision='float32', calibration=str(tmp_path / 'rig.yaml'))
    with NodeProcess('detector', ros_env, params) as node:
        assert node.wait(timeout=120) == 2, node.output()
    lines = [line for line in node.stderr_path.read_text().splitlines() if line.strip()]
    assert len(lines) == 1, node.output()
    assert "parameter 'calibration'" in lines[0] and 'int8' in lines[0], lines
    assert 'Traceback' not in node.output()
