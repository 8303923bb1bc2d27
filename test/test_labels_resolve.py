"""The one label validator (labels.resolve_labels): stamp matching within half a frame
period, unit mistakes named, name maps, image bounds, frame indices, skip-and-count."""
import numpy as np
import pytest

from monet_ros.labels import (
    LabelError,
    LabelOptions,
    LabelRow,
    match_camera_names,
    read_label_rows,
    resolve_labels,
)

T0 = 1_700_000_000_000_000_000
STAMPS = np.array([T0 + round(i * 1e9 / 60) for i in range(10)], np.int64)
CAMERAS = [('cam01', 1080, 1920), ('cam02', 1088, 1920)]
KEYPOINTS = ('nose', 'hip')


def row(stamp=None, frame=None, camera='cam01', keypoint='nose', u=10.0, v=20.0, line=2):
    return LabelRow('labels.csv', line, stamp, frame, camera, keypoint, u, v)


def test_stamps_match_nearest_instant_within_half_a_period():
    # a lab computes t0 + i * (1e9 // 60) (truncating), a few ns off the recording's stamps
    rows = [row(stamp=T0 + i * (10**9 // 60), camera=c, u=float(i), line=i + 2)
            for i in range(10) for c in ('cam01', 'cam02')]
    labels, report = resolve_labels(rows, STAMPS, CAMERAS, KEYPOINTS)
    assert report.kept == 20 and report.total_skipped == 0
    assert labels.stamps == STAMPS.tolist()               # keyed by the recording's stamps
    for i, s in enumerate(STAMPS):
        np.testing.assert_array_equal(labels.points(s, ['cam01', 'cam02'])[:, 0],
                                      [[i, 20.0], [i, 20.0]])
    period = int(np.median(np.diff(STAMPS)))
    gapped = np.delete(STAMPS, 5)                       # instant 5 was not recorded
    # half a period (rounded down) still matches; one ns more does not
    labels, _ = resolve_labels([row(stamp=int(STAMPS[4]) + period // 2)], gapped, CAMERAS,
                               KEYPOINTS)
    assert labels.stamps == [int(STAMPS[4])]
    with pytest.raises(LabelError, match=r'labels.csv:2: field stamp_ns: .* matches no '
                       r'instant: the nearest \(4, .* more than the tolerance'):
        resolve_labels([row(stamp=int(STAMPS[4]) + period // 2 + 1)], gapped, CAMERAS,
                       KEYPOINTS)


@pytest.mark.parametrize('stamp, pattern', [
    (int(STAMPS[4]) // 1_000_000, 'looks like milliseconds'),
    (int(STAMPS[4]) // 1_000, 'looks like microseconds'),
    (int(STAMPS[4]) // 1_000_000_000, 'looks like seconds'),
    (10**30, 'outside the recording'),
    (5, 'outside the recording'),
])
def test_stamp_unit_mistakes_are_named(stamp, pattern):
    with pytest.raises(LabelError, match=r'^labels.csv:7: field stamp_ns: ' + f'.*{pattern}'):
        resolve_labels([row(stamp=stamp, line=7)], STAMPS, CAMERAS, KEYPOINTS)


def test_camera_and_keypoint_names_are_checked_and_mapped():
    bad = row(stamp=int(STAMPS[0]), camera='cam_01')
    with pytest.raises(LabelError, match=r"field camera: 'cam_01' is not a camera of the "
                       r"recording \(cam01, cam02\); did you mean 'cam01'\? \(--camera-map "
                       r'cam_01=cam01\)'):
        resolve_labels([bad], STAMPS, CAMERAS, KEYPOINTS)
    labels, report = resolve_labels([bad], STAMPS, CAMERAS, KEYPOINTS,
                                    LabelOptions(camera_map=('cam_01=cam01',)))
    assert labels.cameras == ['cam01'] and report.kept == 1
    with pytest.raises(LabelError, match=r"field keypoint: 'Nose' is not a keypoint"):
        resolve_labels([row(stamp=int(STAMPS[0]), keypoint='Nose')], STAMPS, CAMERAS,
                       KEYPOINTS)
    labels, _ = resolve_labels([row(stamp=int(STAMPS[0]), keypoint='Nose')], STAMPS, CAMERAS,
                               KEYPOINTS, LabelOptions(keypoint_map={'Nose': 'nose'}))
    assert labels.num_points == 1
    with pytest.raises(LabelError, match="--camera-map: 'cam_01' is not NAME=NEW_NAME"):
        LabelOptions(camera_map=('cam_01',))


@pytest.mark.parametrize('u, v, field', [(1080.0, 5.0, 'u'), (-0.6, 5.0, 'u'),
                                         (5.0, 1920.0, 'v'), (5.0, 1e9, 'v')])
def test_points_outside_the_image_are_errors(u, v, field):
    with pytest.raises(LabelError, match=f'field {field}: .* outside the image of cam01 '
                       r'\(1080x1920'):
        resolve_labels([row(frame=0, u=u, v=v)], STAMPS, CAMERAS, KEYPOINTS)
    # the pixel-edge box itself is inside
    labels, _ = resolve_labels([row(frame=0, u=1079.5, v=-0.5)], STAMPS, CAMERAS, KEYPOINTS)
    assert labels.num_points == 1


def test_frame_indices_incomplete_instants_and_duplicates():
    labels, _ = resolve_labels([row(frame=9, u=3.0)], STAMPS, CAMERAS, KEYPOINTS)
    assert labels.stamps == [int(STAMPS[9])]
    with pytest.raises(LabelError, match=r'field frame: 10 is not an instant of the '
                       r'recording \(0 \.\. 9\)'):
        resolve_labels([row(frame=10)], STAMPS, CAMERAS, KEYPOINTS)
    valid = np.ones(10, bool)
    valid[2] = False
    with pytest.raises(LabelError, match='field frame: instant 2 .* incomplete'):
        resolve_labels([row(frame=2)], STAMPS, CAMERAS, KEYPOINTS, valid=valid)
    with pytest.raises(LabelError, match=r'labels.csv:3: field keypoint: nose of cam01 at '
                       r'instant 1 is labelled twice \(first on line 2\)'):
        resolve_labels([row(frame=1), row(stamp=int(STAMPS[1]) + 3, line=3)], STAMPS,
                       CAMERAS, KEYPOINTS)


def test_skip_bad_labels_drops_and_counts_every_kind():
    rows = [row(frame=0), row(frame=0, camera='camX', line=3), row(frame=0, keypoint='tail',
            line=4), row(stamp=10**30, line=5), row(frame=1, u=1e6, line=6), row(frame=0, line=7)]
    labels, report = resolve_labels(rows, STAMPS, CAMERAS, KEYPOINTS,
                                    LabelOptions(skip_bad=True))
    assert labels.num_points == 1 and report.kept == 1 and report.rows == 6
    assert report.skipped == {'camera': 1, 'keypoint': 1, 'instant': 1, 'bounds': 1,
                              'duplicate': 1}
    text = report.summary()
    assert text.startswith('1 of 6 label rows used; skipped 1 (bounds), 1 (camera)')
    assert 'labels.csv:' in text


def test_frame_indexed_csv_reads(tmp_path):
    path = tmp_path / 'frames.csv'
    path.write_text('frame,camera,keypoint,u,v\n3,cam02,hip,1.25,2.5\n')
    rows = read_label_rows(path)
    assert rows[0].frame == 3 and rows[0].stamp_ns is None and rows[0].line == 2
    labels, _ = resolve_labels(rows, STAMPS, CAMERAS, KEYPOINTS)
    np.testing.assert_array_equal(labels.points(STAMPS[3], ['cam02'])[0, 1], [1.25, 2.5])


def test_cameras_match_file_names_like_anipose():
    files = ['trial_cam1.mp4', 'trial_cam10.mp4', 'trial_cam2.mp4']
    assert match_camera_names(['cam1', 'cam10', 'cam2'], files) == {
        'cam1': 'trial_cam1.mp4', 'cam10': 'trial_cam10.mp4', 'cam2': 'trial_cam2.mp4'}
    with pytest.raises(LabelError, match=r"camera 'cam_01' matches no file \(looks like "
                       r"'cam01.mp4'"):
        match_camera_names(['cam_01'], ['cam01.mp4'])
    with pytest.raises(LabelError, match="camera 'cam3' matches no file"):
        match_camera_names(['cam1', 'cam3'], files)
