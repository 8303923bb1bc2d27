"""`monet process --subjects N --precision int8`: int8 calibrates on the crops a
several-subject run makes (int8_calibration.subject_crops: each subject's crop around its
track and the discovery maps, whole frame or tiles), under its own crops key. Two subjects
of three blobs (helpers.subject_blobs) at 256 px, where discovery detects 4 tiles per
view."""
import shutil

from helpers.blob_net import SIZE, train_blob_net
from helpers.subject_blobs import blob_checkpoint, render, write_two_subjects
import numpy as np
import pytest

from monet_ros.atomic import sha256_file
from monet_ros.cli import main as monet
from monet_ros.crop_rule import TrackedRule, subject_boxes
from monet_ros.int8_calibration import crops_key, subject_crops
from monet_ros.models import Detector
from monet_ros.models.crop import crop_images
from monet_ros.models.quantize import cpu_int8_feature, int8_path_for
from monet_ros.subjects.detection import SubjectsConfig, tile_boxes

T = 12
needs_int8 = pytest.mark.skipif(cpu_int8_feature() is None,
                                reason='no VNNI / AMX-INT8 on this CPU')


@pytest.fixture(scope='module')
def scene(tmp_path_factory):
    root = tmp_path_factory.mktemp('int8-subjects')
    folder, cams, X = write_two_subjects(root / 'rec', T=T, width=256, height=256,
                                         sigma_px=3.0)
    model = blob_checkpoint(train_blob_net(steps=400, sigma=(1.2, 4.0)), root / 'b.pt')
    return folder, cams, X, model


def test_the_subjects_crops_key_names_the_quant():
    config = SubjectsConfig(subjects=3, discovery_tiles=2)
    key = crops_key(True, TrackedRule(margin=0.4, trim=0.0, min_points=4), subjects=config)
    assert key == 'subjects3-d2-m0.4-t0-k4'
    assert int8_path_for('/x/b.pt', 'ab' * 32, key).name == f'b.{"ab" * 8}.{key}.int8.onnx'
    assert crops_key(True, subjects=SubjectsConfig(subjects=1)) == 'tracked-m0.3-t4-k3'
    assert crops_key(False, subjects=config) == 'full'


def test_subject_calibration_crops_are_each_subjects_and_the_discovery_tiles(scene):
    # against crops cut independently: the crop rule's box around each true subject in each
    # view (the float32 net's 3D is within a few cm of it) and the tile of the instant
    folder, cams, X, model = scene
    detector = Detector.from_checkpoint(model, device='cpu', precision='float32')
    rule = TrackedRule(trim=0.0)        # 3 blobs: the robust trim may leave one out
    config = SubjectsConfig(subjects=2, link_mm=450.0)
    crops = subject_crops(folder / 'recording', detector, config, rule, cams)
    assert crops.dtype == np.uint8 and crops.shape[1:] == (SIZE, SIZE, 3)
    # per instant 4 tiles and 2 crops per subject found (discovery in one frame finds both
    # subjects at most instants: 56 crops here), at most the calibration's 64
    assert 6 * 4 <= len(crops) <= 64
    frames = render(cams, X, 3.0)
    tiles = tile_boxes(256, 256, 2)
    subjects, tile = [], []
    for n, t in enumerate(range(0, T, 2)):       # 6 instants taken evenly over 12 frames
        images = [f[t] for f in frames]
        for s in range(2):
            boxes = detector.boxes_for(cams, subject_boxes(cams, X[t, s], rule.margin,
                                                           rule.min_points, trim=0.0))
            subjects.append(crop_images(images, boxes, (SIZE, SIZE)))      # (V, ...)
        tile.append(crop_images(images, np.repeat(tiles[n % 4][None], 4, 0), (SIZE, SIZE)))
    subjects = np.concatenate(subjects).astype(float)
    tile = np.concatenate(tile).astype(float)
    diff_subject = np.abs(crops[:, None] - subjects[None]).mean(axis=(2, 3, 4)).min(1)
    diff_tile = np.abs(crops[:, None] - tile[None]).mean(axis=(2, 3, 4)).min(1)
    # every instant gives each view's next tile, exactly
    tiles_found = diff_tile < 0.5
    assert tiles_found.sum() == 6 * 4, diff_tile
    # the rest are subject crops: the crop rule's around the subjects the step tracked,
    # most near a true subject's (measured: 21 of 32 within 4 grey levels, mean absolute
    # difference per crop; the others at the instants where the subjects pass within
    # 0.3 m, where the one-instant discovery's 3D is off or mixed, up to 17 levels, far
    # from any tile: 8-19)
    near = diff_subject[~tiles_found] < 4.0
    assert near.mean() > 0.6, diff_subject[~tiles_found]


@needs_int8
def test_int8_with_subjects_calibrates_on_its_crops(scene, tmp_path):
    # the quant is made from subject_crops and cached under the subjects crops key (not the
    # one-subject tracked key it used before). Its accuracy against float32 is not asserted
    # here: not measured yet (the machine of this change, an AMD EPYC, has no VNNI)
    folder, cams, X, source = scene
    model = shutil.copy(source, tmp_path / 'b.pt')
    out = tmp_path / 'int8'
    assert monet(['process', str(folder / 'recording'), '--rig', str(folder / 'rig.yaml'),
                  '--model', str(model), '--quiet', '--backend', 'onnxruntime', '--threads',
                  '1', '--subjects', '2', '--link-mm', '450', '--export', 'csv', '--out',
                  str(out), '--precision', 'int8']) == 0
    sha = sha256_file(model)[:16]
    assert [p.name for p in tmp_path.glob('*.int8.onnx')] == [
        f'b.{sha}.subjects2-d2-m0.3-t4-k3.int8.onnx']
    assert (out / 'keypoints3d.csv').is_file()
