"""`monet process`: detector + fusion over a recording, offline, into an MCAP."""
from helpers.recordings import noise_recording, small_checkpoint
import numpy as np
import pytest

from monet_ros.cli import main as monet
from monet_ros.fusion import FusionConfig, fuse_heatmaps
from monet_ros.io import cloud_to_keypoints3d, open_bag
from monet_ros.models import Detector
from monet_ros.models.detector import bfloat16_native


def test_every_frame_is_written_and_equals_the_core_functions(tmp_path, capsys):
    rig, stamps = noise_recording(tmp_path / 'rec', cameras=3, frames=4)
    model = small_checkpoint(tmp_path / 'model.pt')
    out = tmp_path / 'out'
    code = monet(['process', str(tmp_path / 'rec'), '--model', str(model), '--out', str(out),
                  '--no-track', '--heatmaps', '--quiet'])
    assert code == 0
    assert 'monet process: 4 frames (12 views, 0 missing)' in capsys.readouterr().out
    reader = open_bag(out)
    clouds = [m for m in reader.messages(['/monet/keypoints3d'])]
    assert [m.stamp_ns for m in clouds] == stamps
    assert all(m.msg.header.frame_id == 'world' for m in clouds)
    heat_topics = {t for t in reader.topics if t.endswith('/heatmaps')}
    assert heat_topics == {f'/monet/cam{v}/heatmaps' for v in range(3)}
    # The first frame again, straight through the core (full-frame crops, no tracking).
    images = {m.topic: m.msg for m in open_bag(tmp_path / 'rec').messages()
              if m.topic.endswith('image_raw') and m.stamp_ns == stamps[0]}
    frames = [np.frombuffer(images[f'/{c.name}/image_raw'].data, np.uint8)
              .reshape(c.height, c.width, 3) for c in rig]
    # the command's default precision (auto: bfloat16 where native)
    detector = Detector.from_checkpoint(model, device='cpu', precision='auto')
    heat, heat_cams = detector.predict(frames, rig)
    result = fuse_heatmaps(heat, np.stack([c.K for c in heat_cams]), rig, FusionConfig())
    got = cloud_to_keypoints3d(clouds[0].msg, units='m')
    np.testing.assert_allclose(got['X'], result.X.astype(np.float32), rtol=1e-4, atol=1e-4)
    np.testing.assert_array_equal(got['num_views'], result.num_views)


def test_bad_inputs_are_clear_errors(tmp_path, capsys):
    noise_recording(tmp_path / 'rec', cameras=2, frames=1)
    model = small_checkpoint(tmp_path / 'model.pt')
    args = ['process', str(tmp_path / 'rec'), '--out', str(tmp_path / 'out'), '--quiet']
    assert monet(args + ['--model', str(tmp_path / 'nope.pt')]) == 2
    assert 'nope.pt: checkpoint file not found' in capsys.readouterr().err
    assert monet(args + ['--model', str(model), '--cameras', 'cam0', 'cam9']) == 2
    assert "unknown camera 'cam9'" in capsys.readouterr().err
    assert monet(args + ['--model', str(model), '--backend', 'onnxruntime',
                         '--precision', 'bfloat16']) == 2
    assert 'precision bfloat16 needs backend torch' in capsys.readouterr().err
    (tmp_path / 'out').mkdir()
    (tmp_path / 'out' / 'something').write_text('')
    assert monet(args + ['--model', str(model)]) == 2
    assert 'output exists' in capsys.readouterr().err


def test_onnxruntime_backend_writes_the_torch_heatmaps(tmp_path, capsys):
    from monet_ros.io import image_msg_to_heatmaps

    noise_recording(tmp_path / 'rec', cameras=2, frames=2)
    model = small_checkpoint(tmp_path / 'model.pt')
    heat = {}
    for backend in ('torch', 'onnxruntime'):
        out = tmp_path / backend
        assert monet(['process', str(tmp_path / 'rec'), '--model', str(model), '--out',
                      str(out), '--no-track', '--heatmaps', '--quiet', '--backend', backend,
                      '--threads', '1', '--precision', 'float32']) == 0
        heat[backend] = [(m.topic, m.stamp_ns, image_msg_to_heatmaps(m.msg))
                         for m in open_bag(out).messages() if m.topic.endswith('/heatmaps')]
    assert len(heat['torch']) == 4
    assert [h[:2] for h in heat['onnxruntime']] == [h[:2] for h in heat['torch']]
    for (_, _, a), (_, _, b) in zip(heat['torch'], heat['onnxruntime']):
        np.testing.assert_allclose(b, a, atol=1e-4, rtol=0)
    assert list(tmp_path.glob('model.*.onnx'))  # the export, cached beside the checkpoint


@pytest.mark.skipif(not bfloat16_native('cpu'), reason='no native bfloat16 on this CPU')
def test_bfloat16_precision_writes_the_core_bfloat16_heatmaps(tmp_path, capsys):
    """--precision bfloat16 reaches the network: the heatmaps are the core Detector's at
    bfloat16 (not float32's, which differ by ~1e-3 of the peak or more)."""
    from monet_ros.io import image_msg_to_heatmaps

    rig, _ = noise_recording(tmp_path / 'rec', cameras=2, frames=1)
    model = small_checkpoint(tmp_path / 'model.pt')
    out = tmp_path / 'out'
    assert monet(['process', str(tmp_path / 'rec'), '--model', str(model), '--out', str(out),
                  '--no-track', '--heatmaps', '--quiet', '--precision', 'bfloat16']) == 0
    got = {m.topic.split('/')[-2]: image_msg_to_heatmaps(m.msg)
           for m in open_bag(out).messages() if m.topic.endswith('/heatmaps')}
    images = {m.topic: m.msg for m in open_bag(tmp_path / 'rec').messages()
              if m.topic.endswith('image_raw')}
    frames = [np.frombuffer(images[f'/{c.name}/image_raw'].data, np.uint8)
              .reshape(c.height, c.width, 3) for c in rig]
    expected = {precision: Detector.from_checkpoint(model, device='cpu', precision=precision)
                .predict(frames, rig)[0] for precision in ('float32', 'bfloat16')}
    for v, camera in enumerate(rig):
        np.testing.assert_allclose(got[camera.name], expected['bfloat16'][v], atol=1e-4,
                                   rtol=0)
        assert np.abs(got[camera.name] - expected['float32'][v]).max() > 1e-4
