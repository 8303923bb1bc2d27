"""The detector node with precision int8 calibrates on the crops it will make: its track
parameter (and track_* rule, or its fixed box) picks tracked, box or full-frame
calibration crops from the
`calibration` recording, and the quant is cached under that crop mode's name beside the
checkpoint (monet_ros.int8_calibration). The real executable, started as a user would."""
import time

from helpers.recordings import noise_recording, small_checkpoint
from helpers.ros import NodeProcess
import pytest

from monet_ros.atomic import sha256_file
from monet_ros.models.quantize import cpu_int8_feature


def wait_started(node, timeout=120.0):
    """Until the node logs its 'detecting ...' start line (True), or exits (False)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if 'detecting' in node.output():
            return True
        if not node.running():
            return False
        time.sleep(0.1)
    return False


@pytest.mark.skipif(cpu_int8_feature() is None, reason='no VNNI / AMX-INT8 on this CPU')
def test_detector_node_calibrates_int8_on_the_crops_of_its_track_parameter(ros_env, tmp_path):
    rec = tmp_path / 'rec'
    noise_recording(rec, cameras=3, frames=4, compressed=True)
    model = small_checkpoint(tmp_path / 'model.pt')
    sha = sha256_file(model)[:16]
    common = dict(rig=str(rec), model=str(model), device='cpu', backend='onnxruntime',
                  precision='int8', calibration=str(rec))
    for params, key in ((dict(track_margin=0.5), 'tracked-m0.5-t4-k3'),
                        (dict(track=False), 'full'),
                        (dict(track=False, box=[40.0, 30.0, 280.0, 210.0]),
                         'box-40_30_280_210')):
        with NodeProcess('detector', ros_env, {**common, **params}) as node:
            assert wait_started(node), node.output()
            assert 'int8' in node.output(), node.output()
            # the line saying what it calibrated on and which quant it wrote
            assert (f'precision int8: calibrated on 12 crops ({key}) of {rec}; wrote '
                    f'{tmp_path / f"model.{sha}.{key}.int8.onnx"}') in node.output()
            assert node.stop() == 0, node.output()
        assert (tmp_path / f'model.{sha}.{key}.int8.onnx').is_file(), node.output()
    # one quant per crop mode, none used for another
    assert len(list(tmp_path.glob('*.int8.onnx'))) == 3
