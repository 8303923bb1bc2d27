"""The no-ROS parts of several subjects live: which track a detector's crop was cut for
(SubjectsCore.match_crops), the detector's crop slots (crop_rule.TrackedSubjects) and the
keypoints3d cloud's `subject` field (io.fields)."""
from helpers.scenes import ring_rig
import numpy as np
import pytest

from monet_ros.crop_rule import TrackedRule, TrackedSubjects, discovery_due, subject_boxes
from monet_ros.io.fields import cloud_to_arrays, keypoint_cloud_fields
from monet_ros.subjects.detection import SubjectsConfig, SubjectsCore

GRID = (32, 24)      # heatmap (w, h)


def bodies():
    rng = np.random.default_rng(4)
    A = rng.uniform([-0.5, -0.4, 0.6], [-0.2, -0.1, 1.5], (14, 3))
    B = rng.uniform([0.2, 0.1, 0.6], [0.5, 0.4, 1.5], (14, 3))
    return A, B


def test_crops_are_matched_to_the_tracks_they_were_cut_around_whatever_their_order():
    cams = ring_rig(3)
    A, B = bodies()
    core = SubjectsCore(14, 'm', SubjectsConfig(subjects=2))
    # the detector cut its crops around the previous frame's 3D (1 cm off the prediction),
    # in the order B, A in every view, plus one crop around nothing near either
    views, K, sizes = [], [], []
    for v, cam in enumerate(cams):
        for S in (B + 0.01, A + 0.01):
            box = subject_boxes([cam], S)[0]
            views.append(v)
            K.append(cam.crop(box, GRID).K)
            sizes.append(GRID[::-1])
    views.append(0)
    K.append(cams[0].crop(np.array([0.0, 0.0, 40.0, 30.0]), GRID).K)
    sizes.append(GRID[::-1])
    owner = core.match_crops(cams, np.stack([A, B]), views, K, sizes)
    assert owner.tolist() == [1, 0] * 3 + [-1]
    # no hypotheses: every crop is of an unknown subject
    assert (core.match_crops(cams, np.zeros((0, 14, 3)), views, K, sizes) == -1).all()


def test_crop_slots_follow_the_subjects_by_identity_and_the_full_frame_while_fewer():
    cams = ring_rig(2)
    A, B = bodies()
    tracks = TrackedSubjects(TrackedRule(timeout_ns=1_000), 'm')
    full = np.array([[0, 0, c.width, c.height] for c in cams], np.float64)
    assert np.array_equal(tracks.boxes(cams, 5, 2)[:, 2], full)        # nothing yet
    assert np.isnan(tracks.boxes(cams, 5, 2)[:, :2]).all()
    X = np.concatenate([B, A])
    tracks.update(X, np.repeat([9, 4], 14), np.tile(np.arange(14), 2), 100, 14)
    boxes = tracks.boxes(cams, 100, 2)
    np.testing.assert_array_equal(boxes[:, 0], subject_boxes(cams, A))  # identity 4 first
    np.testing.assert_array_equal(boxes[:, 1], subject_boxes(cams, B))
    assert np.isnan(boxes[:, 2]).all()                                  # both tracked
    boxes = tracks.boxes(cams, 100 + 1_001, 2)                          # stale (timeout)
    assert np.isnan(boxes[:, :2]).all() and np.array_equal(boxes[:, 2], full)
    assert np.isnan(tracks.boxes(cams, 100, 2, track=False)[:, :2]).all()
    tracks.update(B, np.full(14, 9), np.arange(14), 200, 14)
    boxes = tracks.boxes(cams, 200, 2, fallback_box=(1.0, 2.0, 30.0, 40.0))
    np.testing.assert_array_equal(boxes[:, 0], subject_boxes(cams, B))
    assert np.isnan(boxes[:, 1]).all()
    assert np.array_equal(boxes[:, 2], [[1.0, 2.0, 30.0, 40.0]] * 2)


def test_the_subject_field_is_added_only_with_subjects():
    X = np.arange(12, dtype=np.float64).reshape(4, 3)
    one = keypoint_cloud_fields(X, units='m')
    assert one['point_step'] == 28
    assert [f[0] for f in one['fields']] == ['x', 'y', 'z', 'confidence',
                                             'reprojection_error', 'num_views', 'keypoint']
    two = keypoint_cloud_fields(X, units='mm', keypoint=[0, 1, 0, 1], subject=[3, 3, 7, 7])
    assert two['point_step'] == 32 and two['row_step'] == 128
    assert two['fields'][:7] == one['fields'] and two['fields'][7] == ('subject', 28, 6, 1)
    raw = np.frombuffer(two['data'].tobytes(), np.uint8).reshape(4, 32)
    assert raw[:, 28:32].copy().view('<u4').ravel().tolist() == [3, 3, 7, 7]
    assert raw[:, 24:28].copy().view('<u4').ravel().tolist() == [0, 1, 0, 1]
    np.testing.assert_allclose(raw[:, :12].copy().view('<f4'), X / 1000, rtol=1e-6)

    class Msg:                                # what cloud_to_arrays reads of a message
        width, height, is_bigendian = 4, 1, False
        point_step, row_step, data = 32, 128, two['data'].tobytes()
        fields = [type('F', (), dict(name=n, offset=o, datatype=d, count=c))
                  for n, o, d, c in two['fields']]
    assert cloud_to_arrays(Msg)['subject'].tolist() == [3, 3, 7, 7]


def test_full_frame_maps_alone_keep_two_subjects_tracked():
    # a detector with track:=false sends only the full frame: discovery finds both in the
    # first frame, then each track takes its instance from the full-frame maps
    from helpers.scenes import cv2_project, gaussian_heatmaps

    cams = ring_rig(3)
    A, B = bodies()
    core = SubjectsCore(14, 'm', SubjectsConfig(subjects=2))
    box, grid = np.array([0.0, 0.0, 640.0, 480.0]), (160, 120)
    identity = {}
    for t in range(6):
        step = np.array([0.02 * t, 0.0, 0.0])
        truth = [A + step, B - step]
        full = []
        for v, cam in enumerate(cams):
            heat = np.zeros((14, grid[1], grid[0]), np.float32)
            for X in truth:
                p = (cv2_project(cam, X) + 0.5) * grid[0] / 640 - 0.5
                heat = np.maximum(heat, gaussian_heatmaps(p, grid[::-1], sigma=1.5))
            full.append((v, heat, cam.crop(box, grid).K))
        r = core.live_frame(cams, 1_000 + t * 33_333_333, [], full)
        assert (r.ids >= 0).sum() == 2, t
        assert r.discovered == (2 if t == 0 else -1)
        for s, ident in zip(r.keep, r.ids):
            X = r.association.X[s]
            d = [np.abs(X - T).max() for T in truth]
            body = int(np.argmin(d))
            assert d[body] < 0.005, (t, d)
            assert identity.setdefault(body, int(ident)) == int(ident)
    assert core.tracker.births == 2


def test_an_instant_without_any_crop_ages_the_tracks():
    # every slot of the instant empty (no view): no subject, the tracks age and die
    core = SubjectsCore(14, 'm', SubjectsConfig(subjects=2))
    A, _ = bodies()
    core.tracker.step(A[None], 0)
    r = core.live_frame([], 100_000_000, [], [])
    assert len(r.ids) == 0 and core.tracker.ids.tolist() == [0]
    core.live_frame([], 700_000_000, [], [])        # max_missed_s 0.5 s
    assert core.tracker.deaths == 1


def test_a_hidden_joint_does_not_take_the_neighbours_peak_with_rival_peaks():
    # subject 0's keypoint is hidden in this view, subject 1's (a rival hypothesis) shows:
    # the crop's nearest peak is the neighbour's; with rival_peaks it is left out
    from monet_ros.geometry import Camera
    from monet_ros.subjects.detection import crop_instances

    cam = Camera(name='c', K=np.array([[50.0, 0, 32], [0, 50.0, 24], [0, 0, 1]]),
                 dist=np.zeros(5), R=np.eye(3), t=np.zeros(3), width=64, height=48)
    heat_cam = cam.crop(np.array([0.0, 0.0, 64.0, 48.0]), (16, 12))
    yy, xx = np.mgrid[0:12, 0:16]
    heat = (0.9 * np.exp(-((xx - 12) ** 2 + (yy - 6) ** 2) / 2))[None, None]
    neighbour = (np.array([12.0, 6.0]) + 0.5) * 4 - 0.5               # source px
    own = np.array([[[10.0, 26.0]]])                                 # (1 crop, 1 kp, 2)
    rivals = neighbour[None, None, None]                             # (1, 1 rival, 1, 2)
    config = SubjectsConfig()
    p, _ = crop_instances(heat.astype(np.float32), [heat_cam], [cam], own, config, 0.1)
    assert np.linalg.norm(p[0, 0] - neighbour) < 1.0                  # taken without
    p, s = crop_instances(heat.astype(np.float32), [heat_cam], [cam], own, config, 0.1,
                          rivals)
    assert np.isnan(p).all() and s[0, 0] == 0.0
    # its own peak, nearer its target than the rival's, stays
    p, _ = crop_instances(heat.astype(np.float32), [heat_cam], [cam], neighbour[None, None],
                          config, 0.1, own[:, None])
    assert np.linalg.norm(p[0, 0] - neighbour) < 1.0


def test_tiled_discovery_maps_keep_two_subjects_tracked():
    # live discovery with tiles (a detector whose network would shrink the 640 x 480 frame
    # more than 2 times sends its 6 tiles of 320 px): the tiles of a view are merged into
    # one view's candidates (discovery finds both, as discover_heatmaps from the same maps
    # does offline), and each subject takes its instance in a view from the tile nearest
    # its joints with the most room (bodies of 100-150 px, at most half a tile's 320 px side:
    # the tiles overlap by half, so one holds each body whole; a larger body is cut by its
    # tile, docs/subjects.md "Live"). Fails before: the tiles were taken as views.
    from helpers.scenes import cv2_project, gaussian_heatmaps

    from monet_ros.subjects.detection import tile_boxes

    cams = ring_rig(3)
    A, B = (S.mean(0) + 0.5 * (S - S.mean(0)) for S in bodies())
    core = SubjectsCore(14, 'm', SubjectsConfig(subjects=2))
    tiles, grid = tile_boxes(640, 480, 2), (80, 80)
    assert len(tiles) == 6
    identity = {}
    for t in range(6):
        step = np.array([0.02 * t, 0.0, 0.0])
        truth = [A + step, B - step]
        full = []
        for v, cam in enumerate(cams):
            for box in tiles:
                heat = np.zeros((14, grid[1], grid[0]), np.float32)
                for X in truth:
                    p = (cv2_project(cam, X) - box[:2] + 0.5) * grid[0] / (box[2] - box[0]) - 0.5
                    heat = np.maximum(heat, gaussian_heatmaps(p, grid[::-1], sigma=1.5))
                full.append((v, heat, cam.crop(box, grid).K))
        if t == 0:
            views = np.array([f[0] for f in full])
            offline, _ = SubjectsCore(14, 'm', SubjectsConfig(subjects=2)).discover_heatmaps(
                [f[1] for f in full], [f[2] for f in full], cams, np.zeros((0, 14, 3)), views)
            assert len(offline) == 2
        r = core.live_frame(cams, 1_000 + t * 33_333_333, [], full)
        assert (r.ids >= 0).sum() == 2, t
        assert r.discovered == (2 if t == 0 else -1)
        assert r.crops == 2 * len(cams)               # one tile per subject and view
        for s, ident in zip(r.keep, r.ids):
            X = r.association.X[s]
            d = [np.abs(X - T).max() for T in truth]
            body = int(np.argmin(d))
            assert d[body] < 0.005, (t, d)
            assert identity.setdefault(body, int(ident)) == int(ident)
    assert core.tracker.births == 2


def _due_frames(stamps, period_s):
    previous, due = None, []
    for i, stamp in enumerate(stamps):
        if discovery_due(stamp, previous, period_s):
            due.append(i)
        previous = stamp
    return due


def test_discovery_is_due_in_the_first_frame_of_each_period_of_the_stamp_clock():
    period_ns = 250_000_000
    start = 1_767_225_600_000_000_000 + 12_345_678
    stamps = [start + round(i * 1e9 / 30) for i in range(100)]      # 30 Hz, 3.3 s
    # brute force: frame 0, then the first frame at or after each multiple of the period
    expected = [0] + [next(i for i, s in enumerate(stamps) if s >= b)
                      for b in range((start // period_ns + 1) * period_ns, stamps[-1] + 1,
                                     period_ns)]
    assert _due_frames(stamps, 0.25) == expected
    assert 13 <= len(expected) <= 15                        # ~one frame in 7.5, not all 100
    assert _due_frames(stamps, 0.0) == list(range(100))     # 0: every frame
    assert _due_frames(stamps, 10.0) == [0]                 # longer than the run: the first
    # frames 1/3 s apart under a 0.25 s period: every frame is the first of its window
    assert _due_frames([start + i * 333_333_333 for i in range(10)], 0.25) == list(range(10))


def test_detectors_that_skip_frames_still_discover_in_the_same_frames():
    # two detectors of one rig see the same stamps; one lets a frame go (stale) that is not
    # the first of its window: both send discovery maps in the same frames
    start = 1_767_225_600_000_000_000
    stamps = [start + round(i * 1e9 / 30) for i in range(60)]
    skipped = [s for i, s in enumerate(stamps) if i not in (3, 11, 20)]
    all_due = {stamps[i] for i in _due_frames(stamps, 0.25)}
    some_due = {skipped[i] for i in _due_frames(skipped, 0.25)}
    assert not {stamps[i] for i in (3, 11, 20)} & all_due   # (the skipped were not due)
    assert some_due == all_due


def test_a_negative_discovery_period_is_refused():
    with pytest.raises(ValueError, match='discovery period'):
        discovery_due(0, None, -0.1)


def test_a_detectors_discovery_tiles_is_read_back_from_its_slot_count():
    # what the fusion node says of a detector whose discovery slots differ from its own:
    # every value that gives the count (tile_boxes counted independently: `tiles` along the
    # shorter side, as many at the same step along the longer one)
    from monet_ros.subjects.detection import discovery_slots, discovery_tiles_for, tile_boxes
    for width, height in ((96, 96), (640, 480), (1920, 1080), (200, 3000)):
        for tiles in range(7):
            count = discovery_slots(width, height, tiles)
            assert count == (len(tile_boxes(width, height, tiles)) if tiles else 1)
            values = discovery_tiles_for(width, height, count)
            assert tiles in values
            assert all(discovery_slots(width, height, v) == count for v in values)
    assert discovery_tiles_for(96, 96, 1) == [0, 1]          # a square frame: one tile
    assert discovery_tiles_for(96, 96, 4) == [2]
    assert discovery_tiles_for(640, 480, 2) == [1]           # 480 px squares, 2 across
    assert discovery_tiles_for(96, 96, 3) == []              # no value gives 3
    assert discovery_tiles_for(96, 96, 0) == []


def test_the_discovery_slot_waits_for_the_next_window_and_the_subject_slots_do_not():
    # TrackedSubjects with discovery_period_s 0.25, frames 0.1 s apart: one subject tracked
    # (N = 2), its crop in every frame; the full frame in frames 0, 3, 5, 8 only (the first
    # of each 0.25 s window, at 0, 0.3, 0.5, 0.8 s)
    cams = ring_rig(2)
    _, B = bodies()
    tracks = TrackedSubjects(TrackedRule(timeout_ns=10**12), 'm', discovery_period_s=0.25)
    tracks.update(B, np.full(14, 9), np.arange(14), 0, 14)
    full = np.array([[0, 0, c.width, c.height] for c in cams], np.float64)
    discovery = []
    for k in range(10):
        boxes = tracks.boxes(cams, k * 100_000_000, 2)
        np.testing.assert_array_equal(boxes[:, 0], subject_boxes(cams, B))
        assert np.isnan(boxes[:, 1]).all()
        discovery.append(bool(np.isfinite(boxes[:, 2]).all()))
        if discovery[-1]:
            assert np.array_equal(boxes[:, 2], full)
    assert discovery == [k in (0, 3, 5, 8) for k in range(10)]
    with pytest.raises(ValueError, match='discovery period'):
        TrackedSubjects(discovery_period_s=-1.0)
