"""`monet pipeline --precision int8` end to end on JPEG cameras: the network quantised once
(calibrated on the tracked crops of the recording, cached beside the checkpoint under that
crop mode's name) before the detector process starts, the views decoded at the crop's
scale in parallel, and every frame fused."""
import sys

from helpers.recordings import noise_recording, small_checkpoint
from helpers.ros import NodeProcess, RosHarness
import pytest
from sensor_msgs.msg import PointCloud2

from monet_ros.io import cloud_to_keypoints3d, header_stamp_ns
from monet_ros.models.quantize import cpu_int8_feature


@pytest.mark.skipif(cpu_int8_feature() is None, reason='no VNNI / AMX-INT8 on this CPU')
def test_int8_pipeline_fuses_every_frame_of_a_jpeg_recording(ros_env, tmp_path):
    _, stamps = noise_recording(tmp_path / 'rec', cameras=3, frames=4, compressed=True)
    model = small_checkpoint(tmp_path / 'model.pt')
    argv = [sys.executable, '-m', 'monet_ros.cli', 'pipeline', '--bag', str(tmp_path / 'rec'),
            '--model', str(model), '--lockstep', '--backend', 'onnxruntime',
            '--precision', 'int8', '--start-delay', '2.0']
    with RosHarness(ros_env) as ros:
        clouds = ros.collect('/monet/keypoints3d', PointCloud2, 100)
        with NodeProcess('pipeline', ros_env, argv=argv) as proc:
            ros.spin_until(lambda: len(clouds) >= len(stamps), timeout=120, process=None)
            assert proc.wait(timeout=60) == 0, proc.output()
    output = proc.output()
    assert 'monet pipeline: precision int8' in output, output
    assert f'monet pipeline: precision int8: calibrated on 12 crops (tracked-m0.3-t4-k3) ' \
        f'of {tmp_path / "rec"}; wrote {tmp_path}/model.' in output, output
    # quantised once, on tracked crops (the detector nodes track, with the default rule)
    assert [p.name.split('.', 2)[2] for p in tmp_path.glob('model.*.int8.onnx')] == \
        ['tracked-m0.3-t4-k3.int8.onnx'], output
    assert [header_stamp_ns(c) for c in clouds] == stamps, output
    for cloud in clouds:
        assert cloud_to_keypoints3d(cloud, units='m')['X'].shape == (14, 3)
    assert f'frames {len(stamps)} fused of {len(stamps)} played' in output
    assert 'never retrieved' not in output
