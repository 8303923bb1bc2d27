"""Distillation with several subjects (issue 39 item 6): the teacher runs as `monet process
--subjects N --filter optim` and each of its identities becomes the pseudo-labels of the
crop rows of the subject it is centred in (learning.distill.match_identities), whatever the
identity numbers: a real recording of two subjects of three coloured blobs walking past
each other (helpers.subject_blobs: 4 cameras, 12 frames, 96x96; the scene of
`monet process --subjects`' own test), labelled for both with
the label ids SWAPPED against the ground truth's slots (label subject 0 is the ground
truth's subject 1), the trained blob net as the teacher. Each subject's crop rows get
pseudo-labels near its own projected ground truth (measured ~0.5 px median), not the other
subject's."""
from helpers.blob_net import train_blob_net
from helpers.subject_blobs import PERIOD, T0, write_two_subjects
import numpy as np
import pytest
import torch

from monet_ros.commands.train_distill import distill_round
from monet_ros.labels import write_labels
from monet_ros.learning.config import TrainConfig
from monet_ros.learning.distill import match_identities
from monet_ros.learning.recording import load_recording
from monet_ros.learning.trainer import Trainer, TrainingData
from monet_ros.subjects.detection import SubjectsConfig

T = 12
LABELLED = (0, 4, 8)                     # instants 9..11 are the held-out tail (0.25)
NAMES = ('a', 'b', 'c')
SWAP = (1, 0)                            # label subject s is the ground truth's SWAP[s]
CONFIG = dict(architecture='small', input_size=64, width=16, batch_labelled=8,
              batch_pseudo=0, batch_unlabeled=0, lr=3e-3, eval_fraction=0.25, device='cpu',
              box_source='labels', precision='float32', distill_rounds=1,
              distill_min_views=2)


def projections(cams, X):
    """(T, V, S, C, 2) px of X (T, S, C, 3), NaN outside the 96x96 images."""
    Tn, S, C, _ = X.shape
    uv = np.stack([cam.project(X.reshape(-1, 3)).reshape(Tn, S, C, 2) for cam in cams], 1)
    inside = ((uv >= -0.5) & (uv <= 95.5)).all(-1)
    return np.where(inside[..., None], uv, np.nan)


@pytest.fixture(scope='module')
def scene(tmp_path_factory):
    torch.set_num_threads(1)
    root = tmp_path_factory.mktemp('distill_subjects')
    folder, cams, X = write_two_subjects(root / 'rec', T=T)
    uv = projections(cams, X)
    rows = [(T0 + PERIOD * t, cam.name, NAMES[c], *uv[t, v, SWAP[s], c], s)
            for t in LABELLED for v, cam in enumerate(cams) for s in (0, 1)
            for c in range(3) if np.isfinite(uv[t, v, SWAP[s], c, 0])]
    write_labels(root / 'labels.csv', rows)
    skeleton = root / 'blobs.yaml'
    skeleton.write_text('name: blobs\nkeypoints: [a, b, c]\nbones: [[a, b], [a, c]]\n')
    return folder, cams, X, uv, root, skeleton, train_blob_net(steps=400, sigma=(1.2, 4.0))


def test_each_subjects_crop_rows_get_its_own_distilled_pseudo_labels(scene, tmp_path):
    folder, cams, X, uv, root, skeleton, net = scene
    rec = load_recording(folder, labels=root / 'labels.csv', skeleton=list(NAMES))
    config = TrainConfig(mode='supervised', steps=1, **CONFIG)
    data = TrainingData(rec, config, (64, 64), (16, 16))
    # with distillation each labelled subject has its own unlabelled rows
    assert data.unlabeled_rows_per_subject() == {0: 6, 1: 6}
    trainer = Trainer(config, data, tmp_path / 'run')
    trainer.model.load_state_dict(net.state_dict())         # the trained blob net teaches
    said = []
    stats = distill_round(trainer, 1, folder / 'recording', rig=folder / 'rig.yaml',
                          skeleton=skeleton, progress=False, say=said.append,
                          subjects=SubjectsConfig(subjects=2, link_mm=450.0))
    print('\n'.join(said))
    assert stats['subjects'] == 2 and stats['kept'] == trainer.distilled_count > 0
    # the teacher ran on every instant and each crop row of those got an identity
    assert stats['frames_unmatched'] == 0 and stats['rows_unmatched'] == 0
    points = trainer.distilled                                   # (num_rows, V, C, 2)
    assert points.shape == (data.num_rows, 4, 3, 2)
    truth = uv[data.row_instants]                                # (R, V, S, C, 2)
    for s in (0, 1):
        mine = data.row_subjects == s
        got = points[mine]
        own = np.linalg.norm(got - truth[mine][:, :, SWAP[s]], axis=-1)
        other = np.linalg.norm(got - truth[mine][:, :, SWAP[1 - s]], axis=-1)
        ok = np.isfinite(got[..., 0])
        # the labelled views get none; the unlabelled rows of the training split do
        assert ok.sum() > 40, (s, ok.sum())
        assert stats['rows_per_subject'][s] >= 5
        print(f'label subject {s}: {ok.sum()} pseudo-labels, median {np.median(own[ok]):.2f} '
              f'px from its ground truth, max {np.max(own[ok]):.2f}; median '
              f'{np.nanmedian(other[ok]):.1f} px from the other subject')
        assert np.median(own[ok]) < 2.0 and np.percentile(own[ok], 90) < 5.0
        assert np.nanmin(other[ok]) > np.percentile(own[ok], 90)
    # a row's pseudo-labels are never on its labelled views, held-out or validation instants
    assert not (np.isfinite(points[..., 0]) & np.isfinite(data.row_labels[..., 0])).any()
    assert not np.isfinite(points[np.isin(data.row_instants, data.held_out)]).any()


def test_match_identities_pairs_by_the_crops_not_by_the_numbers(scene):
    """Two identities whose rows come in either order are each given the crop row centred on
    them (Hungarian per instant); an identity far from every crop, or an instant without
    rows, gives none."""
    folder, cams, X, uv, *_ = scene
    from monet_ros.learning.dataset import boxes_from_points
    t = np.array([2, 2, 5, 5, 7])
    Xr = np.stack([X[2, 1], X[2, 0], X[5, 0], X[5, 1] + [0, 0, 5.0], X[7, 0]])  # far: +5 m up
    row_instants = np.array([2, 2, 5, 5])
    boxes = np.stack([boxes_from_points(uv[2, :, 0], aspect=1.0, margin=0.25),
                      boxes_from_points(uv[2, :, 1], aspect=1.0, margin=0.25),
                      boxes_from_points(uv[5, :, 1], aspect=1.0, margin=0.25),
                      boxes_from_points(uv[5, :, 0], aspect=1.0, margin=0.25)])
    boxes = np.where(np.isfinite(boxes), boxes, [0, 0, 96, 96])
    match, cost = match_identities(Xr, t, row_instants, boxes, cams)
    np.testing.assert_array_equal(match, [1, 0, -1, 2])
    assert np.isinf(cost[2]) and (cost[[0, 1, 3]] < 0.3).all()
    mm, _ = match_identities(Xr * 1000.0, t, row_instants, boxes, cams, units='mm')
    np.testing.assert_array_equal(mm, match)
    # one crop for both rows (a full frame: box_source full): the rows' labels decide
    full = np.broadcast_to([0.0, 0.0, 96.0, 96.0], boxes.shape).copy()
    labels = np.full((4, 4, 3, 2), np.nan)
    labels[0, :2], labels[1, 2:] = uv[2, :2, 0], uv[2, 2:, 1]    # some views, one subject each
    by_label, _ = match_identities(Xr, t, row_instants, full, cams, row_points=labels)
    np.testing.assert_array_equal(by_label[:2], [1, 0])


def teacher_of(folder, *options):
    """train_with_distillation's teacher settings of `monet train ... OPTIONS` (the real
    parser and checks), the labels holding 2 subjects."""
    from monet_ros.cli import build_parser
    from monet_ros.commands.train import check_teacher_options
    args = build_parser().parse_args(['train', str(folder), '--out', 'o', '--distill-rounds',
                                      '1', *options])
    return check_teacher_options(args, True, 2)


def test_the_teacher_options_of_monet_train_reach_the_teacher_in_any_rig_unit(scene,
                                                                               tmp_path):
    """`monet train --link-mm / --duplicate-mm ...` (`monet process --subjects`' options of
    those names, in mm) are the teacher's (before: no such option of `monet train`). The
    blob subjects are 0.32 m across, their keypoints 0.34 m apart: --link-mm 450 links
    them and each subject's rows get its own 3D; --link-mm 300 links no keypoint, so the
    teacher finds no subject (a misread unit would link everything in m or nothing in mm);
    --duplicate-mm 1000 takes the two subjects, 0.7 m apart, for one body: only one
    subject's rows get pseudo-labels. The rig in mm gives the same pseudo-labels as in m."""
    from monet_ros.geometry import load_rig, save_rig
    from monet_ros.geometry.units import rescale
    from monet_ros.subjects import AssociationConfig
    from monet_ros.subjects.tracking import TrackerConfig
    folder, cams, X, uv, root, skeleton, net = scene
    teacher = teacher_of(folder, '--link-mm', '450', '--gate-mm', '350')
    # written out: the settings a user typed, the rest `monet process`' defaults
    assert teacher['subjects'] == SubjectsConfig(subjects=2, link_mm=450.0)
    assert teacher['tracker'] == TrackerConfig(gate_mm=350.0)
    assert teacher['association'] == AssociationConfig()
    assert teacher_of(folder)['subjects'] == SubjectsConfig(subjects=2)
    rigs = {'m': folder / 'rig.yaml', 'mm': tmp_path / 'rig_mm.yaml'}
    save_rig(rigs['mm'], rescale(load_rig(rigs['m']), 'mm'))
    rec = load_recording(folder, labels=root / 'labels.csv', skeleton=list(NAMES))
    config = TrainConfig(mode='supervised', steps=1, **CONFIG)
    data = TrainingData(rec, config, (64, 64), (16, 16))

    def teach(units, *options):
        trainer = Trainer(config, TrainingData(rec, config, (64, 64), (16, 16)),
                          tmp_path / f'{units}{"".join(options)}')
        trainer.model.load_state_dict(net.state_dict())
        said = []
        stats = distill_round(trainer, 1, folder / 'recording', rig=rigs[units],
                              skeleton=skeleton, progress=False, say=said.append,
                              **teacher_of(folder, *options))
        return stats, trainer.distilled.copy(), said[0]

    stats, points, said = teach('m', '--link-mm', '450')
    assert 'as `monet process --subjects 2 --link-mm 450 --filter optim`' in said, said
    assert stats['rows_unmatched'] == 0 and stats['kept'] > 80
    truth = uv[data.row_instants]
    for s in (0, 1):
        mine = data.row_subjects == s
        own = np.linalg.norm(points[mine] - truth[mine][:, :, SWAP[s]], axis=-1)
        ok = np.isfinite(own)
        assert ok.sum() > 40 and np.median(own[ok]) < 2.0, (s, ok.sum())
    for units in ('m', 'mm'):
        none = teach(units, '--link-mm', '300')[0]
        assert none['kept'] == 0 and none['rows_per_subject'] == {0: 0, 1: 0}, (units, none)
    one, one_points, said = teach('m', '--duplicate-mm', '1000')
    assert '--duplicate-mm 1000' in said
    assert 0 < one['kept'] < stats['kept'] and 0 in one['rows_per_subject'].values()
    one_mm, one_mm_points, _ = teach('mm', '--duplicate-mm', '1000')
    assert one_mm['kept'] == one['kept']
    np.testing.assert_allclose(one_mm_points, one_points, atol=1e-3, equal_nan=True)


@pytest.mark.parametrize('labels, options, error', [
    ('labels.csv', ['--link-mm', '450'], '--link-mm applies only with --distill-rounds N'),
    ('labels0.csv', ['--distill-rounds', '1', '--gate-mm', '300'],
     '--gate-mm applies only with labels of several subjects'),
    ('labels.csv', ['--distill-rounds', '1', '--link-mm', '-1'],
     "--link-mm: SubjectsConfig: parameter 'link_mm': must be > 0.0, got -1.0"),
])
def test_a_teacher_option_monet_train_cannot_use_is_one_line(scene, tmp_path, capsys, labels,
                                                            options, error):
    from monet_ros.cli import main as monet
    folder, cams, X, uv, root, skeleton, net = scene
    if not (root / 'labels0.csv').exists():          # subject 0's rows only
        lines = (root / 'labels.csv').read_text().splitlines()
        (root / 'labels0.csv').write_text('\n'.join(
            [lines[0].rsplit(',', 1)[0]] + [r.rsplit(',', 1)[0] for r in lines[1:]
                                            if r.endswith(',0')]) + '\n')
    code = monet(['train', str(folder), '--labels', str(root / labels), '--skeleton',
                  str(skeleton), '--out', str(tmp_path / 'run'), '--steps', '1',
                  '--architecture', 'small', '--device', 'cpu', *options])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and error in err[0], err
