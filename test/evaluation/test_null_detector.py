"""The image-blind null row: the mean labelled pose in the crop. It must sit where the
labels sit on average, and a trained detector must beat it on every ground-truth column."""
from helpers.blobs import blob_recording
import numpy as np
import pytest
import torch

from monet_ros.evaluation.evaluate import evaluate_detector
from monet_ros.evaluation.null_detector import mean_pose_positions, null_detector
from monet_ros.learning.config import TrainConfig
from monet_ros.learning.trainer import Trainer, TrainingData
from monet_ros.models import decode_heatmaps
from monet_ros.models.detector import Detector

CONFIG = dict(architecture='small', input_size=48, width=16, lr=3e-3, eval_fraction=0.25,
              device='cpu', sigma=1.0, checkpoint_every=1000)


@pytest.fixture(scope='module')
def data():
    torch.set_num_threads(1)
    rec = blob_recording(num_views=4, T=32, C=3, labelled=(1, 6, 11, 16, 21))
    config = TrainConfig(mode='supervised', steps=150, **CONFIG)
    return config, TrainingData(rec, config, (48, 48), (12, 12))


def test_null_heatmaps_peak_at_the_mean_labelled_position_in_the_crop(data):
    config, data = data
    # independent: labels (pixel centres) -> the nominal training box -> 12x12 heatmap px
    pts = []
    for t, v in np.argwhere(np.isfinite(data.labels[..., 0]).any(axis=2)):
        x0, y0, x1, y1 = data.boxes[t, v]
        scale = np.array([12 / (x1 - x0), 12 / (y1 - y0)])
        pts.append((data.labels[t, v] + 0.5 - [x0, y0]) * scale - 0.5)
    want = np.mean(pts, axis=0)
    np.testing.assert_allclose(mean_pose_positions(data), want, atol=1e-9)
    detector = null_detector(data, config.sigma)
    images = [np.zeros((c.height, c.width, 3), np.uint8) + 128 for c in data.cameras]
    heat, _ = detector.predict(images, data.cameras)
    peaks, _ = decode_heatmaps(heat)
    np.testing.assert_allclose(peaks, np.broadcast_to(want, peaks.shape), atol=0.05)


def test_null_scores_worse_than_a_trained_model_on_every_ground_truth_column(data):
    config, data = data
    trainer = Trainer(config, data)
    trainer.run(progress=False)
    trained = Detector(trainer.model, trainer.metadata(), device='cpu')
    rows = {name: evaluate_detector(det, data.recording, data.held_out, data.boxes, name)
            for name, det in (('null', null_detector(data, config.sigma)),
                              ('supervised', trained))}
    null, model = rows['null'], rows['supervised']
    for key in ('error2d_mean', 'error2d_median', 'error3d_mean'):
        assert model.extra[key] < null.extra[key], (key, model.extra, null.extra)
    for alpha in (0.05, 0.1, 0.2):
        assert model.pck.at(alpha) > null.pck.at(alpha), (alpha, model.pck, null.pck)
