"""The learner executable in its own process, with a real detector process: /monet/model
announcements, hot reload between frames, services, SIGKILL mid-write, refused checkpoints."""
import hashlib
import json
import random
import signal
import time

from diagnostic_msgs.msg import DiagnosticArray
from helpers.blob_bag import write_blob_folder
from helpers.blobs import blob_recording
from helpers.ros import NodeProcess, RosHarness
import numpy as np
import pytest
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import String
from std_srvs.srv import Trigger
import torch

from monet_ros.io import (
    camera_info_from_camera,
    header_stamp_ns,
    image_msg_to_heatmaps,
    numpy_to_image_msg,
)
from monet_ros.models import Detector, build_model, load_checkpoint, save_checkpoint
from monet_ros.models.checkpoint import FORMAT
from monet_ros.nodes.qos import LATCHED

KEYPOINTS = ['k0', 'k1', 'k2']
NET = dict(input_size=[48, 48], width=16)
TINY = dict(batch_labelled=4, batch_pseudo=4, batch_unlabeled=1, views_per_instant=3,
            lr=3e-3, eval_fraction=0.25, device='cpu', threads=1, validate_instants=4)
T0 = 1_700_000_000_000_000_000


@pytest.fixture(scope='module')
def scene(tmp_path_factory):
    root = tmp_path_factory.mktemp('learner')
    rec = blob_recording(num_views=4, T=24, C=3, labelled=(2, 9), label_views=(0, 1))
    folder = write_blob_folder(rec, root / 'data')
    torch.manual_seed(0)
    save_checkpoint(root / 'init.pt', build_model('small', 3, **NET), {'keypoints': KEYPOINTS})
    return folder, root / 'init.pt', rec


def sha256(path):
    return hashlib.sha256(open(path, 'rb').read()).hexdigest()


def reference(checkpoint, image, camera, box):
    """What the detector must publish for `image` with the weights of `checkpoint` (at the
    node's default precision, auto)."""
    detector = Detector(*load_checkpoint(checkpoint), device='cpu', precision='auto')
    boxes = detector.boxes_for([camera], np.array([box]))
    return detector.predict([image], [camera], boxes, keep_aspect=False)[0][0]


class Frames:
    """Lockstep camera: publishes one frame (camera_info + image, new stamp) and waits for
    the detector's heatmaps of that stamp before the next; counts frames left unanswered."""

    def __init__(self, ros, camera, image, node):
        self.ros, self.camera, self.image, self.node = ros, camera, image, node
        self.image_pub = ros.publisher(f'/{camera.name}/image_raw', Image)
        self.info_pub = ros.publisher(f'/{camera.name}/camera_info', CameraInfo)
        self.heat = ros.collect(f'/monet/{camera.name}/heatmaps', Image, 100)
        self.stamp = T0
        self.sent = self.unanswered = 0

    def answer(self, stamp):
        return next((h for h in self.heat if header_stamp_ns(h) == stamp), None)

    def next(self, timeout=10.0):
        """Heatmaps (C, h, w) of a new frame, or None when none came within `timeout`."""
        self.stamp += 100_000_000
        stamp = self.stamp
        self.info_pub.publish(camera_info_from_camera(self.camera, stamp, self.camera.name))
        self.image_pub.publish(numpy_to_image_msg(self.image, stamp, self.camera.name))
        self.sent += 1
        if not self.ros.spin_until(lambda: self.answer(stamp) is not None, timeout,
                                   process=self.node):
            self.unanswered += 1
            return None
        return image_msg_to_heatmaps(self.answer(stamp))

    def first(self, tries=30):
        """The first answered frame (discovery may swallow the very first messages)."""
        self.ros.wait_for_subscribers(self.image_pub, process=self.node)
        for _ in range(tries):
            heat = self.next(timeout=2.0)
            if heat is not None:
                self.sent = self.unanswered = 0
                return heat
        raise AssertionError(f'the detector never answered\n{self.node.output()}')


def learner_status(diagnostics):
    """{key: value} of the latest learner DiagnosticStatus."""
    for msg in reversed(diagnostics):
        for status in msg.status:
            if status.name == 'monet learner':
                return {kv.key: kv.value for kv in status.values}
    return None


def call(ros, client, process, timeout=60.0):
    future = client.call_async(Trigger.Request())
    assert ros.spin_until(future.done, timeout, process=process), 'no service response'
    return future.result()


def detector_params(folder, init, camera):
    return dict(rig=str(folder / 'rig.yaml'), cameras=[camera.name], model=str(init),
                box=[0.0, 0.0, float(camera.width), float(camera.height)], track=False,
                device='cpu', threads=1, batch_wait_ms=5.0)


def learner_params(folder, init, out, **more):
    return dict(bags=[str(folder)], out=str(out), model=str(init), **TINY, **more)


def test_learner_announces_detector_reloads_between_frames_and_services(scene, ros_env,
                                                                         tmp_path):
    folder, init, rec = scene
    camera, image = rec.cameras[0], rec.frames[0][3]
    box = (0.0, 0.0, camera.width, camera.height)
    out = tmp_path / 'out'
    # every finite checkpoint is announced here (the criterion is tested in test_online.py)
    params = learner_params(folder, init, out, checkpoint_every=4, keep_checkpoints=0,
                            publish_tolerance_px=1e6)
    with RosHarness(ros_env) as ros, \
            NodeProcess('detector', ros_env, detector_params(folder, init, camera)) as det:
        frames = Frames(ros, camera, image, det)
        models = ros.collect('/monet/model', String, LATCHED)
        diagnostics = ros.collect('/diagnostics', DiagnosticArray, 50)
        before = frames.first()
        np.testing.assert_allclose(before, reference(init, image, camera, box), atol=1e-4)
        with NodeProcess('learner', ros_env, params) as learner:
            # the stream runs (lockstep) while the learner trains and announces
            heats = []
            deadline = time.monotonic() + 240
            while time.monotonic() < deadline:
                heat = frames.next()
                heats.append(heat)
                assert learner.running(), learner.output()
                if len(models) >= 2 and heat is not None and \
                        np.abs(heat - before).max() > 1e-3:
                    break
            assert len(models) >= 2, f'{len(models)} announcements\n{learner.output()}'
            assert frames.unanswered == 0, f'{frames.unanswered} of {frames.sent} frames ' \
                f'without heatmaps across the reloads\n{det.output()}'
            announced = [json.loads(m.data) for m in models]
            steps = [a['step'] for a in announced]
            assert steps == sorted(steps) and steps[0] % 4 == 0
            for a in announced:
                assert a['sha256'] == sha256(a['path'])
                assert load_checkpoint(a['path'])[1]['step'] == a['step']
                assert np.isfinite(a['metrics']['reprojection_px'])
                # the default mode, reprojection: L_L + L_B (the pseudo-labels' loss) + L_R
                assert set(a['metrics']) >= {'epipolar_divergence', 'loss_L', 'loss_B',
                                             'loss_R'}
            # the new heatmaps are those of an announced checkpoint, not the start model's
            last = heats[-1]
            assert any(np.allclose(last, reference(a['path'], image, camera, box), atol=1e-4)
                       for a in announced)

            # services: pause (steps stop), save (a checkpoint of the paused step), resume
            pause = ros.node.create_client(Trigger, '/monet/learner/pause')
            resume = ros.node.create_client(Trigger, '/monet/learner/resume')
            save = ros.node.create_client(Trigger, '/monet/learner/save_checkpoint')
            for client in (pause, resume, save):
                assert client.wait_for_service(timeout_sec=30)
            reply = call(ros, pause, learner)
            assert reply.success, reply.message
            paused_at = int(reply.message.split()[3])
            diagnostics.clear()
            assert ros.spin_until(lambda: len(diagnostics) >= 3, 30, learner)
            assert learner_status(diagnostics)['state'] == 'paused'
            assert int(learner_status(diagnostics)['step']) == paused_at
            reply = call(ros, save, learner)
            assert reply.success, reply.message
            saved = out / 'checkpoints' / f'step_{paused_at:06d}.pt'
            assert str(saved) in reply.message
            assert load_checkpoint(saved)[1]['step'] == paused_at
            assert call(ros, resume, learner).success
            assert ros.spin_until(lambda: int((learner_status(diagnostics) or {'step': 0})
                                              ['step']) > paused_at, 60, learner)
            status = learner_status(diagnostics)
            # steps went on (above); the rate is a figure (3 decimals), not checked here
            assert status['state'] == 'training' and float(status['steps_per_s']) >= 0
            assert {'loss_L', 'loss_B', 'loss_R'} <= set(status)     # reprojection: no L_E
            assert learner.stop(signal.SIGINT, timeout=60) == 0, learner.output()
        for _ in range(3):                     # the stream goes on without the learner
            assert frames.next() is not None
        assert det.stop(signal.SIGINT) == 0
    assert 'loaded new weights' in det.output()


def test_sigkill_mid_write_leaves_only_whole_checkpoints_and_resume(scene, ros_env, tmp_path):
    folder, init, _ = scene
    out = tmp_path / 'out'
    params = learner_params(folder, init, out, checkpoint_every=1, keep_checkpoints=0,
                            publish_tolerance_px=1e6)
    with RosHarness(ros_env) as ros:
        models = ros.collect('/monet/model', String, LATCHED)
        with NodeProcess('learner', ros_env, params) as learner:
            assert ros.spin_until(lambda: len(models) >= 3, 240, learner), learner.output()
            ros.spin_for(random.uniform(0.0, 0.5))      # somewhere in a write, most likely
            learner.stop(signal.SIGKILL)
        for path in out.rglob('*.pt'):      # every visible file is whole
            if path.name == 'trainer_state.pt':
                torch.load(path, weights_only=True)
            else:
                load_checkpoint(path)
        for message in models:
            info = json.loads(message.data)
            assert sha256(info['path']) == info['sha256']
        published = json.loads((out / 'published.json').read_text())
        assert sha256(published['path']) == published['sha256']
        state_step = torch.load(out / 'trainer_state.pt', weights_only=True)['step']

        # restarted: temporaries gone, the last announcement re-announced (latched), then on
        models.clear()
        late = ros.collect('/monet/model', String, LATCHED)
        with NodeProcess('learner', ros_env, params) as learner:
            assert ros.spin_until(lambda: any(json.loads(m.data)['step'] > state_step
                                              for m in late), 240, learner), learner.output()
            # /monet/model keeps the last value (depth 1): a late subscriber sees the
            # re-announcement, or a newer model if one came first; never an older one
            first = json.loads(late[0].data)
            assert first['step'] >= published['step']
            if first['step'] == published['step']:
                assert first['sha256'] == published['sha256']
            assert learner.stop(signal.SIGTERM, timeout=60) == 0, learner.output()
        assert f'resumed at step {state_step}' in learner.output()
        assert not list(out.rglob('.*.tmp'))


def test_detector_refuses_broken_announcements_and_keeps_running(scene, ros_env, tmp_path):
    folder, init, rec = scene
    camera, image = rec.cameras[1], rec.frames[1][5]
    box = (0.0, 0.0, camera.width, camera.height)
    torch.manual_seed(7)
    good = tmp_path / 'good.pt'
    save_checkpoint(good, build_model('small', 3, **NET), {'keypoints': KEYPOINTS})
    truncated = tmp_path / 'truncated.pt'
    truncated.write_bytes(good.read_bytes()[:len(good.read_bytes()) // 2])
    four = tmp_path / 'four_keypoints.pt'
    save_checkpoint(four, build_model('small', 4, **NET), {'keypoints': KEYPOINTS + ['k3']})
    alien = tmp_path / 'alien_architecture.pt'   # small weights declared as a CPM
    payload = torch.load(good, weights_only=True)
    payload['metadata']['architecture'] = 'cpm'
    assert payload['format'] == FORMAT
    torch.save(payload, alien)
    want_init = reference(init, image, camera, box)
    with RosHarness(ros_env) as ros, \
            NodeProcess('detector', ros_env, detector_params(folder, init, camera)) as det:
        frames = Frames(ros, camera, image, det)
        announce = ros.publisher('/monet/model', String, LATCHED)
        np.testing.assert_allclose(frames.first(), want_init, atol=1e-4)
        for path, digest in ((truncated, sha256(truncated)), (four, sha256(four)),
                             (alien, sha256(alien)), (good, '0' * 64)):
            announce.publish(String(data=json.dumps({'path': str(path), 'sha256': digest,
                                                     'step': 1})))
            for _ in range(3):
                np.testing.assert_allclose(frames.next(), want_init, atol=1e-4)
        announce.publish(String(data=json.dumps({'path': str(good), 'sha256': sha256(good),
                                                 'step': 2})))
        want_good = reference(good, image, camera, box)
        for _ in range(50):                   # swapped between two frames
            heat = frames.next()
            if not np.allclose(heat, want_init, atol=1e-4):
                break
        np.testing.assert_allclose(heat, want_good, atol=1e-4)
        assert frames.unanswered == 0
        assert det.stop(signal.SIGINT) == 0
    output = det.output()
    assert output.count('/monet/model rejected, keeping the current weights') == 4, output
    assert 'truncated.pt: not a readable checkpoint' in output
    assert 'four_keypoints.pt' in output and 'differ from the running model' in output
    assert 'alien_architecture.pt' in output
    assert 'does not match the announced' in output
    assert 'loaded new weights' in output and 'good.pt' in output
