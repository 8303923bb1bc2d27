"""Detector.predict: one batched forward over cameras, heatmaps + virtual cameras K_heat = S K."""
from helpers.rigs import random_points, random_rig
import numpy as np
import pytest
import torch

from monet_ros.models import build_model, save_checkpoint
from monet_ros.models.crop import crop_images
from monet_ros.models.detector import Detector, images_to_tensor

NAMES = ['p0', 'p1', 'p2', 'p3']


@pytest.fixture(scope='module')
def setup():
    rng = np.random.default_rng(0)
    cameras = random_rig(rng, 3, width=320, height=240)
    images = rng.integers(0, 256, size=(3, 240, 320, 3), dtype=np.uint8)
    torch.manual_seed(0)
    model = build_model('small', len(NAMES), width=16).eval()
    for module in model.modules():
        if isinstance(module, torch.nn.BatchNorm2d):
            module.running_var.uniform_(0.5, 1.5)
    return cameras, images, model


def test_predict_shapes_and_full_frame_cameras(setup):
    cameras, images, model = setup
    detector = Detector(model, {'keypoints': NAMES}, device='cpu')
    heat, heat_cameras = detector.predict(images, cameras)
    assert heat.shape == (3, 4, 64, 64) and heat.dtype == np.float32
    assert len(heat_cameras) == 3
    for camera, heat_camera in zip(cameras, heat_cameras):
        assert (heat_camera.width, heat_camera.height) == (64, 64)
        # full 320x240 frame padded to a square box (0, -40, 320, 280): scale 64/320
        s = 64 / 320
        S = np.array([[s, 0, 0.5 * s - 0.5], [0, s, (0.5 + 40) * s - 0.5], [0, 0, 1]])
        np.testing.assert_allclose(heat_camera.K, S @ camera.K, atol=1e-12)


def test_predict_crop_box_gives_k_heat_equal_s_k(setup):
    cameras, images, model = setup
    detector = Detector(model, {'keypoints': NAMES}, device='cpu')
    boxes = np.array([[40.0, 30.0, 200.0, 190.0], [100.5, 20.25, 260.5, 180.25],
                      [-20.0, 100.0, 60.0, 180.0]])
    heat, heat_cameras = detector.predict(images, cameras, boxes)
    assert heat.shape == (3, 4, 64, 64)
    rng = np.random.default_rng(1)
    X = random_points(rng, 10)
    for camera, heat_camera, (x0, y0, x1, y1) in zip(cameras, heat_cameras, boxes):
        sx, sy = 64 / (x1 - x0), 64 / (y1 - y0)
        S = np.array([[sx, 0, (0.5 - x0) * sx - 0.5], [0, sy, (0.5 - y0) * sy - 0.5], [0, 0, 1]])
        np.testing.assert_allclose(heat_camera.K, S @ camera.K, atol=1e-12)
        # a 3D point lands where the crop of its original projection lands
        uv = camera.project(X)
        expected = (np.c_[uv, np.ones(len(uv))] @ S.T)[:, :2]
        np.testing.assert_allclose(heat_camera.project(X), expected, atol=1e-9)


def test_predict_equals_the_unfused_model_and_is_batch_independent(setup):
    cameras, images, model = setup
    detector = Detector(model, {'keypoints': NAMES}, device='cpu')
    boxes = np.array([[40.0, 30.0, 200.0, 190.0], [0.0, 0.0, 240.0, 240.0],
                      [80.0, 0.0, 320.0, 240.0]])
    heat, _ = detector.predict(images, cameras, boxes)
    crops = crop_images(images, boxes, (256, 256))
    with torch.inference_mode():
        reference = model(images_to_tensor(crops))[-1].numpy()
    assert np.allclose(heat, reference, atol=1e-4 * np.abs(reference).max())
    single, _ = detector.predict(images[1:2], cameras[1:2], boxes[1:2])
    assert np.allclose(single[0], heat[1], atol=1e-5 * np.abs(heat).max())
    # the caller's model is untouched (not fused, same mode)
    assert any(isinstance(m, torch.nn.BatchNorm2d) for m in model.modules())


def test_keep_aspect_grows_boxes(setup):
    cameras, images, model = setup
    detector = Detector(model, {'keypoints': NAMES}, device='cpu')
    box = np.array([[100.0, 100.0, 200.0, 140.0]])
    np.testing.assert_allclose(detector.boxes_for(cameras[:1], box), [[100, 70, 200, 170]])
    np.testing.assert_allclose(detector.boxes_for(cameras[:1], box, keep_aspect=False), box)


def test_bad_input_is_named(setup):
    cameras, images, model = setup
    detector = Detector(model, {'keypoints': NAMES}, device='cpu')
    with pytest.raises(ValueError, match='2 images but 3 cameras'):
        detector.predict(images[:2], cameras)
    with pytest.raises(ValueError, match="'cam0'.*uint8"):
        detector.predict(images.astype(np.float32), cameras)
    with pytest.raises(ValueError, match="'cam0' is 160x120 but the camera is 320x240"):
        detector.predict(images[:, :120, :160], cameras)
    with pytest.raises(ValueError, match='boxes must be'):
        detector.predict(images, cameras, np.zeros((2, 4)))
    with pytest.raises(ValueError, match='keypoints has 3 names'):
        Detector(model, {'keypoints': NAMES[:3]})


def test_from_checkpoint(setup, tmp_path):
    cameras, images, model = setup
    path = tmp_path / 'small.pt'
    save_checkpoint(path, model, {'keypoints': NAMES, 'step': 3})
    detector = Detector.from_checkpoint(path)
    assert detector.device.type == ('cuda' if torch.cuda.is_available() else 'cpu')
    assert detector.keypoints == NAMES and detector.metadata['step'] == 3
    direct = Detector(model, {'keypoints': NAMES}, device=detector.device)
    a, _ = detector.predict(images, cameras)
    b, _ = direct.predict(images, cameras)
    np.testing.assert_array_equal(a, b)
