"""subjects.detection: the discovery's grouping rule and its config."""
import numpy as np
import pytest

from monet_ros.config import ConfigError
from monet_ros.subjects.detection import SubjectsConfig, group_points


def test_two_whole_subjects_never_merge_through_a_pair_closer_than_the_link():
    # subject A: keypoints 0, 1, 2 in a column 0.3 apart; subject B the same 0.45 to the
    # side: A's keypoint 0 and B's keypoint 1 are 0.54 apart, within the link (0.6), which
    # plain single linkage would follow into one group
    A = np.array([[0.0, 0, 1.6], [0.0, 0, 1.3], [0.0, 0, 1.0]])
    B = A + [0.45, 0.0, 0.0]
    loose = np.array([[3.0, 3.0, 0.0]])
    points = np.concatenate([B, A, loose])
    keypoint = np.array([0, 1, 2, 0, 1, 2, 1])
    views = np.array([3, 3, 3, 4, 4, 4, 2])
    groups = group_points(points, keypoint, views, link=0.6)
    # most keypoints first, then most views: A (4 views each) before B
    assert [g.tolist() for g in groups] == [[3, 4, 5], [0, 1, 2], [6]]
    groups = group_points(points[:6], keypoint[:6], views[:6], link=0.2)   # too short
    assert [g.tolist() for g in groups] == [[3], [4], [5], [0], [1], [2]]


def test_no_points_no_groups():
    assert group_points(np.zeros((0, 3)), np.zeros(0, int), np.zeros(0, int), 0.6) == []


@pytest.mark.parametrize('field, value', [('subjects', 0), ('candidates', 0),
                                          ('link_mm', 0.0), ('crop_peaks', 99),
                                          ('duplicate_mm', -1.0), ('min_score', -0.1),
                                          ('discovery_tiles', -1), ('settle_frames', -1),
                                          ('settle_ratio', 0.5), ('settle_px', 0.0)])
def test_config_names_the_bad_field(field, value):
    with pytest.raises(ConfigError, match=field):
        SubjectsConfig(**{field: value})


def test_only_recently_matched_tracks_get_crops_at_most_n():
    # the rule of the module docstring, step 1: tracks matched within crop_missed frames,
    # at most N, the most recently matched first; a track missed longer still lives in the
    # tracker (its identity kept for a later match) but gets no crop
    from types import SimpleNamespace

    from monet_ros.subjects.detection import SubjectsStep

    step = SubjectsStep(SimpleNamespace(keypoints=['a', 'b', 'c']), 'm',
                        SubjectsConfig(subjects=2, crop_missed=2))
    # three tracks for two crop slots: the tracker here holds more identities than N (resolve
    # gives it at most N subjects, and it bears at most N identities: tracking step 5)
    step.tracker.max_tracks = None
    body = np.array([[0.0, 0.0, 1.6], [0.0, 0.0, 1.3], [0.0, 0.0, 1.0]])
    bodies = np.stack([body, body + [2.0, 0, 0], body + [0, 2.0, 0]])

    def frame(k, subjects):
        before = dict(zip(step.tracker.ids.tolist(), step._missed.tolist()))
        ids = step.tracker.step(bodies[subjects], k * 33_333_333)
        step.count_misses(before, ids)
        return step.tracker.ids[step.cropped_tracks()].tolist()

    assert frame(0, [0, 1, 2]) == [0, 1]            # three born, N = 2: the oldest two
    assert frame(1, [2, 0]) == [0, 2]               # 1 missed once: still allowed, but 0, 2
    assert frame(2, [0]) == [0, 2]                  # 2 missed once, 1 twice: 0, 2
    assert frame(3, [1]) == [1, 0]                  # 1 back (same identity), 0 missed once
    assert frame(4, []) == [1]                      # 0 missed twice now
    assert frame(5, []) == []                       # all missed twice or more: none
    assert step.tracker.ids.tolist() == [0, 1, 2]   # alive (max_missed_s 0.5 s)


def test_a_joint_decoded_by_two_subjects_stays_with_the_body_it_fits():
    from monet_ros.subjects.detection import shared_joints

    # two bodies 1 m apart, keypoints 0-3 in a column; subject 1's keypoint 2 was decoded
    # from subject 0 (1 cm from subject 0's): it is 1 m from subject 1's other joints
    A = np.array([[0.0, 0, 1.6], [0.0, 0, 1.3], [0.0, 0, 1.0], [0.0, 0, 0.7]])
    B = A + [1.0, 0, 0]
    B[2] = A[2] + [0.01, 0, 0]
    X = np.stack([B, A])                     # the captured subject first: order is no help
    drop = shared_joints(X, near=0.1)
    assert drop.tolist() == [[False, False, True, False], [False] * 4]
    # independently: median distance of the shared joint to each subject's other joints
    fit = [np.median(np.linalg.norm(np.delete(S, 2, 0) - S[2], axis=-1)) for S in X]
    assert fit[0] > fit[1]
    # apart (more than `near`), missing, or one subject: nothing goes
    assert not shared_joints(X, near=0.005).any()
    X[1, 2] = np.nan
    assert not shared_joints(X, near=0.1).any()
    assert not shared_joints(X[:1], near=0.1).any()


def test_a_captured_joint_is_restarted_and_its_crop_takes_its_own_peak():
    # the capture: a track whose joint was decoded from the neighbour predicts it there, and
    # the per-crop rule (the peak nearest the prediction) decodes the neighbour again; once
    # the joint is restarted the crop (centred on its own body) takes its highest peak
    from types import SimpleNamespace

    from monet_ros.geometry import Camera
    from monet_ros.subjects.detection import SubjectsStep, crop_instances
    from monet_ros.subjects.tracking import TrackerConfig

    cam = Camera(name='c', K=np.array([[50.0, 0, 32], [0, 50.0, 24], [0, 0, 1]]),
                 dist=np.zeros(5), R=np.eye(3), t=np.zeros(3), width=64, height=48)
    heat_cam = cam.crop(np.array([0.0, 0.0, 64.0, 48.0]), (16, 12))
    yy, xx = np.mgrid[0:12, 0:16]
    own, neighbour = (4, 6), (12, 6)         # heatmap px (x, y): own peak higher
    heat = (0.9 * np.exp(-((xx - own[0]) ** 2 + (yy - own[1]) ** 2) / 2)
            + 0.6 * np.exp(-((xx - neighbour[0]) ** 2 + (yy - neighbour[1]) ** 2) / 2))
    heat = heat[None, None].astype(np.float32)                        # (1 crop, 1 kp)
    source = lambda p: (np.array(p) + 0.5) * 4 - 0.5                  # noqa: E731
    config = SubjectsConfig()

    step = SubjectsStep(SimpleNamespace(keypoints=['a', 'b']), 'm', SubjectsConfig(subjects=2),
                        tracker=TrackerConfig(min_keypoints=1))
    # joint a projects near the neighbour's peak (captured); joint b is its own
    captured = np.array([[[0.6, 0.0, 2.0], [0.0, 0.5, 2.0]]])
    ids = step.tracker.step(captured, 0)
    target = cam.project(step.tracker.predicted(33_333_333)[0, :1])[None]  # (1, 1, 2)
    p, _ = crop_instances(heat, [heat_cam], [cam], target, config, 0.1)
    assert np.linalg.norm(p[0, 0] - source(neighbour)) < 2.0           # today's rule: captured
    step.restart(ids, np.array([[True, False]]))
    assert np.isnan(step.tracker.predicted(33_333_333)[0, 0]).all()
    assert np.isfinite(step.tracker.predicted(33_333_333)[0, 1]).all()
    p, _ = crop_instances(heat, [heat_cam], [cam], np.full((1, 1, 2), np.nan), config, 0.1)
    assert np.linalg.norm(p[0, 0] - source(own)) < 2.0                 # restarted: its own
    own_joint = captured.copy()
    own_joint[0, 0, 0] = 0.0
    assert step.tracker.step(own_joint, 66_666_666).tolist() == [0]   # its other joint matches
    assert step.tracker.ids.tolist() == [0] and step.tracker.started.all()


def test_joints_not_linked_to_their_subjects_body_go():
    from monet_ros.subjects.detection import detached_joints

    # a body of four keypoints in a column (0.3 m apart) whose keypoint 2 is a ghost 1.9 m
    # away (triangulated from different subjects' peaks in different views); the other
    # subject whole
    A = np.array([[0.0, 0, 1.6], [0.0, 0, 1.3], [0.0, 0, 1.0], [0.0, 0, 0.7]])
    B = A + [1.0, 0, 0]
    A[2] = [1.9, 0.0, 1.0]
    X = np.stack([A, B])
    drop = detached_joints(X, link=0.65)
    assert drop.tolist() == [[False, False, True, False], [False] * 4]
    # independently: the ghost's nearest other joint of its subject is beyond the link
    nearest = np.linalg.norm(np.delete(A, 2, 0) - A[2], axis=-1).min()
    assert nearest > 0.65
    # with a link longer than that it is linked: nothing goes
    assert not detached_joints(X, link=nearest + 0.01).any()
    # keypoint 1 missing: keypoints 0 and 3 are 0.9 m apart, three lone joints: no largest
    # group, nothing goes; with a 1 m link 0 and 3 are the body and the ghost goes
    X[0, 1] = np.nan
    assert not detached_joints(X, link=0.65)[0].any()
    assert detached_joints(X, link=1.0)[0].tolist() == [False, False, True, False]
    # one joint alone stays; no subject at all
    one = np.full((1, 4, 3), np.nan)
    one[0, 1] = [5.0, 5.0, 5.0]
    assert not detached_joints(one, link=0.6).any()
    assert detached_joints(np.zeros((0, 4, 3)), link=0.6).shape == (0, 4)


def test_a_limb_linked_only_to_itself_goes_with_the_body_kept():
    from monet_ros.subjects.detection import detached_joints

    # six joints of a body within 0.3 m of the next, and an arm of three (shoulder, elbow,
    # wrist) 0.3 m apart but 1.5 m from the body: taken from elsewhere, it goes
    body = np.array([[0.0, 0, z] for z in (1.7, 1.5, 1.2, 1.0, 0.7, 0.4)])
    arm = np.array([[1.5, 0, z] for z in (1.5, 1.2, 0.9)])
    X = np.concatenate([body[:3], arm, body[3:]])[None]              # the arm at 3..5
    drop = detached_joints(X, link=0.6)
    assert drop[0].tolist() == [False] * 3 + [True] * 3 + [False] * 3
    # independently: single linkage by hand (the arm's nearest body joint is beyond the link)
    gap = np.linalg.norm(arm[:, None] - body[None], axis=-1).min()
    assert gap > 0.6
    # two groups of equal size: both stay
    X = np.concatenate([body[:3], arm])[None]
    assert not detached_joints(X, link=0.6).any()
    # a rig in mm: the same joints go with the link in mm
    X = 1000 * np.concatenate([body[:3], arm, body[3:]])[None]
    assert (detached_joints(X, link=600.0) == drop).all()


def test_a_subject_seen_by_fewer_cameras_keeps_its_place_among_n():
    # a frame of 3 hypotheses (0: the outer subject, cut by the image borders, 1 and 2:
    # two subjects passing each other) on 8 cameras; the association found 4 subjects,
    # most cameras first: A (7 cameras, mostly hypothesis 1's crops), B (6, hypothesis
    # 2's), C (6, a mixture of 1's and 2's leftovers) and D (5, all hypothesis 0's: the
    # outer subject). Most cameras first would keep A, B, C and push D out as extra.
    from monet_ros.subjects.detection import claimed_first

    _ = -1
    instance = np.array([
        [1, 1, 1, 1, 1, 2, 1, _],        # A
        [2, 2, 2, _, 2, _, 2, 2],        # B
        [_, _, _, 2, _, 1, _, 1],        # C: only 3 cameras of its own...
        [0, 0, _, 0, 0, 0, _, _],        # D
    ])
    instance[2, :3] = [2, 1, 2]          # ...and 3 more: 6 cameras, a mixture
    assert ((instance >= 0).sum(1) == [7, 6, 6, 5]).all()
    order = claimed_first(instance, np.arange(4), 3)
    assert order.tolist() == [3, 0, 1, 2]                    # D (h 0), A (h 1), B (h 2), C
    assert sorted(order[:3].tolist()) == [0, 1, 3]           # N = 3 keeps D, not C
    # independently: the subject holding most of each hypothesis' crops
    assert [int(np.argmax((instance == h).sum(1))) for h in range(3)] == [3, 0, 1]
    # a hypothesis whose crops are in no subject claims none; duplicates left out of keep
    # (here B) are not claimed; no hypotheses, no subjects
    assert claimed_first(instance, np.array([0, 2, 3]), 5).tolist() == [3, 0, 2]
    assert claimed_first(instance, np.arange(4), 0).tolist() == [0, 1, 2, 3]
    assert claimed_first(instance, np.zeros(0, np.int64), 3).tolist() == []


def _two_view_crops(bodies, peak_values):
    """Two cameras (64 x 48 px, heatmaps 16 x 12 over the whole image) and, per view and
    body, a hand-made crop map (C, 12, 16) with a Gaussian of height peak_values[b] at each
    of body b's joints projected: -> cameras, v_idx, h_idx, heat, heat_cameras."""
    from monet_ros.geometry import Camera

    K = np.array([[50.0, 0, 32], [0, 50.0, 24], [0, 0, 1]])
    cameras = [Camera(name=n, K=K, dist=np.zeros(5), R=np.eye(3), t=np.asarray(t, float),
                      width=64, height=48)
               for n, t in (('a', (0.0, 0.0, 0.0)), ('b', (-0.5, -0.3, 0.0)))]
    yy, xx = np.mgrid[0:12, 0:16]
    v_idx, h_idx, heat, heat_cameras = [], [], [], []
    for v, cam in enumerate(cameras):
        for b, (joints, value) in enumerate(zip(bodies, peak_values)):
            px = (cam.project(joints) + 0.5) / 4 - 0.5                 # heatmap px (C, 2)
            heat.append((value * np.exp(-((xx - px[:, :1, None]) ** 2
                                          + (yy - px[:, 1:, None]) ** 2) / 2)
                         ).astype(np.float32))
            heat_cameras.append(cam.crop(np.array([0.0, 0.0, 64.0, 48.0]), (16, 12)))
            v_idx.append(v)
            h_idx.append(b)
    return cameras, v_idx, h_idx, heat, heat_cameras


def test_a_subject_of_weak_peaks_is_not_tracked():
    # issue 39: on a recording of one person, a hypothesis discovered from secondary
    # full-frame peaks got crops that decoded 14 joints of peak values 0.15-0.5 (the
    # person's: 0.92-0.97), tracked as a second subject. Two hypotheses here: a body whose
    # crops peak at 0.9 and a ghost whose crops peak at 0.3, both geometrically consistent.
    from monet_ros.subjects.detection import SubjectsCore, weak_subjects
    from monet_ros.subjects.tracking import TrackerConfig

    body = np.array([[-0.3, 0.0, 2.0], [-0.3, 0.2, 2.0], [-0.2, 0.1, 2.0]])
    ghost = np.array([[0.3, -0.1, 2.1], [0.35, 0.1, 2.1], [0.3, 0.2, 2.1]])
    crops = _two_view_crops([body, ghost], [0.9, 0.3])
    cameras, crops = crops[0], crops[1:]
    hyp = np.stack([body, ghost])
    for min_score, kept in ((0.5, [body]), (0.2, [body, ghost])):
        core = SubjectsCore(3, 'm', SubjectsConfig(subjects=2, min_score=min_score),
                            tracker=TrackerConfig(min_keypoints=1))
        r = core.resolve(cameras, 0, hyp, *crops)
        assert r.weak == 2 - len(kept) and r.duplicates == 0
        assert (r.ids >= 0).sum() == len(kept)
        X = r.association.X[r.keep]
        for joints in kept:          # each body kept is found where it is, the ghost not
            assert np.nanmin(np.linalg.norm(X - joints, axis=-1).mean(-1)) < 0.02
        assert len(core.tracker.ids) == len(kept)
        # independently: the crops' map maxima (per joint, mean over the views)
        heat, h_idx = np.array(crops[2]), np.array(crops[1])
        expected = [np.median(heat[h_idx == b].max((2, 3)).mean(0)) for b in (0, 1)]
        assert np.allclose(np.sort(np.nanmedian(r.association.score, -1)),
                           np.sort(expected), atol=0.01)
        assert expected[1] < 0.3 < 0.7 < expected[0]
    # the rule itself: median over the triangulated joints; none triangulated: weak
    score = np.array([[0.9, 0.2, np.nan, 0.8], [0.3, 0.6, 0.4, np.nan],
                      [np.nan] * 4, [0.5, 0.5, 0.5, 0.5]])
    assert weak_subjects(score, 0.5).tolist() == [False, True, True, False]
    assert weak_subjects(np.zeros((0, 4)), 0.5).tolist() == []


def test_foreign_views_are_the_instances_of_another_hypothesis_crop():
    # the rule of the module docstring, step 4, on hand-made slots: 2 subjects, 4 views,
    # 2 keypoints, 3 hypotheses (2: a live crop of unknown joints); written out by hand
    from monet_ros.subjects.detection import foreign_views

    instance = np.array([[0, 0, 1, 2],       # home 0 (2 of 4); view 2 hypothesis 1's crop
                         [1, 1, 0, -1]])     # home 1; view 2 is hypothesis 0's crop
    known = np.array([True, True, False])
    present = np.ones((2, 4, 2), bool)
    present[1, 3] = False                             # subject 1 unseen in view 3
    drop = foreign_views(instance, known, present, min_views=2)
    expected = np.zeros((2, 4, 2), bool)
    expected[0, 2] = True           # (its view 3 stays: hypothesis 2 knew no joint)
    expected[1, 2] = True
    assert drop.tolist() == expected.tolist()
    # a keypoint left with fewer than min_views other views keeps its foreign view
    assert not foreign_views(instance, known, present, min_views=3)[1].any()
    present[1, 0, 1] = False        # subject 1's keypoint 1: views 1 and 2 only
    drop = foreign_views(instance, known, present, min_views=2)
    assert drop[1, 2].tolist() == [True, False]
    # a tie between two hypotheses: no home, nothing foreign; no hypotheses, nothing
    tie = np.array([[0, 1, 0, 1]])
    assert not foreign_views(tie, known, np.ones((1, 4, 2), bool), 2).any()
    assert foreign_views(np.zeros((0, 4), np.int64), known, np.zeros((0, 4, 2), bool),
                         2).shape == (0, 4, 2)
    assert not foreign_views(instance, np.zeros(0, bool), present, 2).any()


def _behind_in_one_view():
    """Three cameras (no distortion) and two bodies of 4 keypoints: B stands behind A in
    camera 2, each of its joints on the ray of A's joint scaled 1.4 from that camera and
    shifted 2 cm to the side, so in camera 2 B's joints project about 4 px from A's and in
    cameras 0 and 1 far from them; B's keypoint 3 is below the image in cameras 0 and 1.
    Per view and body, a crop map (the whole image, 320 x 240 for 640 x 480) with a
    Gaussian at each of the body's joints projected by OpenCV; A's crop in camera 2
    decodes A 6 px low (a poor decode). -> cameras, A, B, v_idx, h_idx, heat,
    heat_cameras (hypothesis 0: A, 1: B)."""
    from helpers.scenes import cv2_project, ring_rig

    cams = ring_rig(3, distortion=(0.0, 0.0, 0.0, 0.0, 0.0))
    A = np.array([[0.0, 0.0, 1.5], [0.0, 0.05, 1.2], [0.05, 0.0, 0.9], [0.0, -0.05, 0.6]])
    ray = A.mean(0) - cams[2].center
    side = np.cross(ray, [0.0, 0.0, 1.0])
    B = cams[2].center + 1.4 * (A - cams[2].center) + 0.02 * side / np.linalg.norm(side)
    grid = (320, 240)
    yy, xx = np.mgrid[0:grid[1], 0:grid[0]]
    v_idx, h_idx, heat, heat_cameras = [], [], [], []
    for v, cam in enumerate(cams):
        for h, body in enumerate((A, B)):
            uv = cv2_project(cam, body) + ([0.0, 6.0] if (v, h) == (2, 0) else 0.0)
            px = (uv + 0.5) / 2 - 0.5                                    # map px (C, 2)
            heat.append((0.9 * np.exp(-((xx - px[:, :1, None]) ** 2
                                        + (yy - px[:, 1:, None]) ** 2) / 4.5)
                         ).astype(np.float32))
            heat_cameras.append(cam.crop(np.array([0.0, 0.0, 640.0, 480.0]), grid))
            v_idx.append(v)
            h_idx.append(h)
    return cams, A, B, v_idx, h_idx, heat, heat_cameras


def test_a_view_from_the_neighbours_crop_is_left_out_of_the_subjects_joints():
    # issue 39: two subjects within 1 m lie on nearly the same epipolar lines in some
    # camera pairs, and the association can give a subject the instance that the
    # neighbour's crop decoded in such a view: it pulls the subject's 3D. Here (camera 2,
    # B behind A) the pairs of A's instances with B's crop in camera 2 have all 4 keypoints
    # in common (B's instances in cameras 0 and 1 only 3) and are merged first
    # (association step 2): A's subject takes B's crop there, B's subject A's crop. With
    # foreign_views that view is left out of the subject's joints seen in at least 2 other
    # views, and their 3D is the triangulation of the other views
    import cv2

    from monet_ros.subjects.detection import SubjectsCore
    from monet_ros.subjects.tracking import TrackerConfig

    cams, A, B, *crops = _behind_in_one_view()
    hyp = np.stack([A, B])
    runs = {}
    for on in (False, True):
        core = SubjectsCore(4, 'm', SubjectsConfig(subjects=2, foreign_views=on),
                            tracker=TrackerConfig(min_keypoints=1))
        r = core.resolve(cams, 0, hyp, *crops)
        rows = r.keep[np.argsort(r.ids)]                 # identity 0: A, 1: B
        assert r.association.instance[rows].tolist() == [[0, 0, 1], [1, 1, 0]]   # setup
        runs[on] = r, rows
    (off, (oA, oB)), (r, (sA, sB)) = runs[False], runs[True]
    a_off, a = off.association, r.association
    # without the rule B's decode in camera 2 pulls A's joints by millimetres
    assert np.linalg.norm(a_off.X[oA] - A, axis=-1).min() > 0.004
    # with it: A's 4 keypoints and B's 0, 1, 2 lose camera 2; B's keypoint 3 keeps it (no
    # other view of it: below the image in cameras 0 and 1)
    assert r.foreign == 7 and off.foreign == 0
    assert not a.inliers[sA, 2].any() and np.isnan(a.points2d[sA, 2]).all()
    assert a.scores2d[sA, 2].tolist() == [0.0] * 4
    # independently: OpenCV's triangulation of each joint from cameras 0 and 1
    for s, truth, joints in ((sA, A, (0, 1, 2, 3)), (sB, B, (0, 1, 2))):
        p = a.points2d[s]
        for c in joints:
            Xh = cv2.triangulatePoints(cams[0].P, cams[1].P, p[0, c].reshape(2, 1),
                                       p[1, c].reshape(2, 1))
            assert np.allclose(a.X[s, c], Xh[:3, 0] / Xh[3, 0], atol=1e-6)
            assert np.linalg.norm(a.X[s, c] - truth[c]) < 5e-4
    # the joint the rule leaves alone is that of the run without it
    assert np.array_equal(a.X[sB, 3], a_off.X[oB, 3], equal_nan=True)
    assert a.points2d[sB, 2, 3].tolist() == a_off.points2d[oB, 2, 3].tolist()


def test_discovery_tiles_cover_the_frame_overlapping_by_half():
    # the rule of the module docstring, step 1a, written out by hand for a 320 x 240 frame:
    # 2 tiles along the 240 px side -> side 240 / 1.5 = 160, step 80: x 0, 80, 160 and
    # y 0, 80; 3 along it -> side 120, step 60, the last x flush with the edge (200)
    from monet_ros.subjects.detection import tile_boxes

    boxes = tile_boxes(320, 240, 2)
    assert boxes.tolist() == [[x, y, x + 160, y + 160] for y in (0, 80)
                              for x in (0, 80, 160)]
    boxes = tile_boxes(320, 240, 3)
    assert sorted({b[0] for b in boxes.tolist()}) == [0, 60, 120, 180, 200]
    assert sorted({b[1] for b in boxes.tolist()}) == [0, 60, 120]
    assert np.allclose(boxes[:, 2:] - boxes[:, :2], 120)
    # one tile: a square of the shorter side, slid along the longer one
    assert tile_boxes(240, 320, 1).tolist() == [[0, 0, 240, 240], [0, 80, 240, 320]]
    # every pixel of the frame lies in some tile
    for tiles in (1, 2, 3, 4):
        b = tile_boxes(640, 360, tiles)
        assert b[:, :2].min() == 0 and b[:, 2].max() == 640 and b[:, 3].max() == 360
        xs, ys = np.meshgrid(np.arange(640) + 0.5, np.arange(360) + 0.5)
        inside = ((xs[..., None] >= b[:, 0]) & (xs[..., None] <= b[:, 2])
                  & (ys[..., None] >= b[:, 1]) & (ys[..., None] <= b[:, 3]))
        assert inside.any(-1).all()


def test_a_views_tiles_give_its_highest_peaks_one_per_blob():
    # two views, one keypoint; view 0 has 2 tiles, view 1 one (maps in any order). View
    # 0: tile a sees a blob at (100, 50) (0.9) and one at (30, 30) (0.4); tile b sees the
    # first blob 3 px off (0.8: the same blob, within the radius) and another at (200, 60)
    # (0.7). With k = 2: (100, 50) 0.9 and (200, 60) 0.7, by hand.
    from monet_ros.subjects.detection import merge_peaks

    nan = np.nan
    pts = np.array([[[[100.0, 50.0], [30.0, 30.0]]],          # view 0, tile a
                    [[[5.0, 5.0], [nan, nan]]],               # view 1
                    [[[103.0, 50.0], [200.0, 60.0]]]])        # view 0, tile b
    conf = np.array([[[0.9, 0.4]], [[0.6, 0.0]], [[0.8, 0.7]]])
    views = np.array([0, 1, 0])
    p, c = merge_peaks(pts, conf, views, 2, 2, radius=7.5)
    assert p.shape == (2, 1, 2, 2) and c.shape == (2, 1, 2)
    assert p[0, 0].tolist() == [[100.0, 50.0], [200.0, 60.0]]
    assert c[0, 0].tolist() == [0.9, 0.7]
    assert p[1, 0, 0].tolist() == [5.0, 5.0] and np.isnan(p[1, 0, 1]).all()
    assert c[1, 0].tolist() == [0.6, 0.0]
    # a smaller radius keeps the shifted blob as the second peak; k = 3 adds the weak one
    p, c = merge_peaks(pts, conf, views, 2, 3, radius=2.0)
    assert c[0, 0].tolist() == [0.9, 0.8, 0.7]
    p, c = merge_peaks(pts, conf, views, 2, 3, radius=7.5)
    assert c[0, 0].tolist() == [0.9, 0.7, 0.4]


def test_a_second_group_of_a_discovered_body_is_not_a_new_subject():
    # step 1e: two groups of one body (points of its keypoints seen twice, a few cm
    # apart, that the constrained linkage cannot put in one group) -> one hypothesis;
    # another body 0.6 m away is one
    from monet_ros.subjects.detection import repeated_body

    A = np.array([[0.0, 0, 1.6], [0.0, 0, 1.3], [0.0, 0, 1.0], [0.1, 0, 0.5]])
    B = A + [0.6, 0.0, 0.0]
    second = A + [0.05, 0.02, 0.0]
    second[3] = np.nan                           # fewer keypoints: compared on the common
    assert repeated_body(second, [A], near=0.4)
    assert not repeated_body(B, [A], near=0.4)
    assert repeated_body(B, [A, B + 0.1], near=0.4)
    assert not repeated_body(A, [], near=0.4)
    none = np.full((4, 3), np.nan)
    none[3] = A[3] + 0.01
    assert not repeated_body(none, [np.where(np.arange(4)[:, None] < 3, A, np.nan)], 0.4)
    # the median: one keypoint far off (a limb of the neighbour) does not make it a body
    # of its own
    odd = second.copy()
    odd[0] += [1.0, 0.0, 0.0]
    assert repeated_body(odd, [A], near=0.4)


def test_tiles_seeing_one_body_twice_discover_it_once():
    # discovery (steps 1a-e) on 3 cameras, each with 2 tiles' maps showing the one body:
    # tile a at its joints, tile b 12 px to the right (a poor decode, farther than the
    # merge radius, so both stay among the candidates and triangulate a second body a few
    # cm from the first). With N = 2: one hypothesis, its 4 keypoints within 5 cm of the
    # body, the other group counted as repeated.
    from helpers.scenes import cv2_project, ring_rig

    from monet_ros.subjects.detection import SubjectsCore

    cams = ring_rig(3, distortion=(0.0, 0.0, 0.0, 0.0, 0.0))
    A = np.array([[0.0, 0.0, 1.5], [0.0, 0.05, 1.2], [0.05, 0.0, 0.9], [0.0, -0.05, 0.6]])
    grid = (320, 240)
    yy, xx = np.mgrid[0:grid[1], 0:grid[0]]
    heat, heat_cameras, views = [], [], []
    for v, cam in enumerate(cams):
        for shift in (0.0, 12.0):
            px = (cv2_project(cam, A) + [shift, 0.0] + 0.5) / 2 - 0.5          # map px
            heat.append((0.9 * np.exp(-((xx - px[:, :1, None]) ** 2
                                        + (yy - px[:, 1:, None]) ** 2) / 4.5)
                         ).astype(np.float32))
            heat_cameras.append(cam.crop(np.array([0.0, 0.0, 640.0, 480.0]), grid))
            views.append(v)
    core = SubjectsCore(4, 'm', SubjectsConfig(subjects=2))
    hyp, counts = core.discover_heatmaps(heat, heat_cameras, cams, np.zeros((0, 4, 3)),
                                         views)
    assert len(hyp) == 1
    assert (np.linalg.norm(hyp[0] - A, axis=-1) < 0.05).all()
    assert counts['repeated'] == 4


def _level_ring(hidden=()):
    """Five cameras (no distortion) on a ring 3 m out at the height of two bodies' keypoint
    0 (1.45 m, the plane of the camera centres: there every epipolar line of that keypoint
    is the same image row, so any peak of it in one view agrees with any in another), A and
    B 0.67 m apart, 4 keypoints each. Per view one whole-frame map (320 x 240 for 640 x
    480) with Gaussians at both bodies' joints projected by OpenCV, the crop of both
    hypotheses there (the full-frame map the live fusion gives a discovered subject);
    hidden: (view, keypoint) of A not drawn. A's hypothesis has a ghost keypoint 0: the
    meeting point of camera 4's ray through A's and camera 2's ray through B's (0.61 m
    from A's). -> cameras, A, B, hyp (2, 4, 3), v_idx, h_idx, heat, heat_cameras."""
    from helpers.scenes import cv2_project, look_at

    from monet_ros.geometry import Camera

    level = 1.45
    cams = []
    for i in range(5):
        angle = 2 * np.pi * i / 5 + 0.2
        centre = (3.0 * np.cos(angle), 3.0 * np.sin(angle), level)
        R, t = look_at(centre, (0.0, 0.0, level - 0.3))
        K = np.array([[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]])
        cams.append(Camera(f'c{i}', K, np.zeros(5), R, t, 640, 480))
    A = np.array([[-0.3, 0.0, level], [-0.3, 0.05, 1.2], [-0.25, 0.0, 0.9], [-0.3, -0.05, 0.6]])
    B = A + [0.65, 0.15, 0.0]
    # the ghost: in the plane z = level, camera 4's ray through A[0] meets camera 2's
    # through B[0]
    d4, d2 = A[0] - cams[4].center, B[0] - cams[2].center
    s = np.linalg.solve(np.stack([d4[:2], -d2[:2]], 1), (cams[2].center - cams[4].center)[:2])
    ghost = cams[4].center + s[0] * d4
    hyp = np.stack([A, B])
    hyp[0, 0] = ghost
    grid = (320, 240)
    yy, xx = np.mgrid[0:grid[1], 0:grid[0]]
    v_idx, h_idx, heat, heat_cameras = [], [], [], []
    for v, cam in enumerate(cams):
        maps = np.zeros((4, grid[1], grid[0]))
        for body, name in ((A, 'A'), (B, 'B')):
            px = (cv2_project(cam, body) + 0.5) / 2 - 0.5                 # map px (C, 2)
            g = 0.9 * np.exp(-((xx - px[:, :1, None]) ** 2 + (yy - px[:, 1:, None]) ** 2) / 4.5)
            for c in range(4):
                if name == 'B' or (v, c) not in hidden:
                    maps[c] = np.maximum(maps[c], g[c])
        for h in (0, 1):
            v_idx.append(v)
            h_idx.append(h)
            heat.append(maps.astype(np.float32))
            heat_cameras.append(cam.crop(np.array([0.0, 0.0, 640.0, 480.0]), grid))
    return cams, A, B, hyp, v_idx, h_idx, heat, heat_cameras


def _resolve(settle_frames, scene, stamp=0, core=None, tracked=0):
    from monet_ros.subjects.detection import SubjectsCore
    from monet_ros.subjects.tracking import TrackerConfig

    cams, A, B, hyp, *crops = scene
    core = core or SubjectsCore(4, 'm', SubjectsConfig(subjects=2, settle_frames=settle_frames),
                                tracker=TrackerConfig(min_keypoints=1))
    assert len(core.hypotheses(stamp)) == tracked     # the tracks given crops (step 1)
    r = core.resolve(cams, stamp, hyp, *crops, tracked=tracked)
    a = r.association
    rows = [int(np.argmin([np.nanmedian(np.linalg.norm(a.X[s] - T, axis=-1)) for s in r.keep]))
            for T in (A, B)]
    return core, r, [r.keep[i] for i in rows]


def test_a_ghost_joint_of_a_mixed_two_view_pair_is_solved_again_while_settling():
    # issue 39, the live start-up ghost: A's hypothesis (discovered this frame) has keypoint
    # 0 at the meeting point of two subjects' rays. Each crop takes the peak nearest it: A's
    # in cameras 1 and 4, B's in camera 2, and every pair of them meets with zero residual
    # (the level ring). The robust triangulation takes the first of those tied pairs (views
    # 2 and 4: the ghost itself, which is then dropped as detached from A's other joints);
    # without the tie rule the SVD's rounding chose, and a CPU kept the mixed pair 1-2,
    # 0.36 m from A's joint. Either way the joint is not A's. While the track settles it is
    # solved again from all its crops' peaks by consistency
    import cv2

    scene = _level_ring()
    cams, A, B = scene[:3]
    _, off, (oA, oB) = _resolve(0, scene)
    a = off.association
    assert not np.linalg.norm(a.X[oA, 0] - A[0]) < 0.3 and off.settled == 0
    _, r, (sA, sB) = _resolve(3, scene)
    a = r.association
    assert r.settled == 1
    assert a.inliers[sA, :, 0].sum() >= 4
    assert np.linalg.norm(a.X[sA, 0] - A[0]) < 1e-3
    # independently: OpenCV's triangulation of the new 2D of two of its views
    v0, v1 = np.flatnonzero(a.inliers[sA, :, 0])[:2]
    Xh = cv2.triangulatePoints(cams[v0].P, cams[v1].P, a.points2d[sA, v0, 0].reshape(2, 1),
                               a.points2d[sA, v1, 0].reshape(2, 1))
    assert np.linalg.norm(Xh[:3, 0] / Xh[3, 0] - A[0]) < 1e-3
    # the other joints and B are those of the run without the rule
    assert np.array_equal(a.X[sA, 1:], off.association.X[oA, 1:])
    assert np.array_equal(a.X[sB], off.association.X[oB])


def test_a_genuine_two_view_joint_is_kept_while_settling():
    # A's keypoint 3 shows only in cameras 1 and 2 (hidden in the others, where B's shows
    # in the crop): two views where A's other joints have five. The rule looks at it
    # (fewer than half the views) and keeps it: no other pair of its crops' peaks agrees
    # better (B's peaks are B's: taken by B's subject)
    scene = _level_ring(hidden={(0, 3), (3, 3), (4, 3)})
    scene[3][0] = scene[1]                                        # no ghost: A's hypothesis
    A = scene[1]
    _, off, (oA, _) = _resolve(0, scene)
    _, r, (sA, _) = _resolve(3, scene)
    a = r.association
    assert a.inliers[sA, :, 3].tolist() == [False, True, True, False, False]
    assert r.settled == 0
    assert np.array_equal(a.X, off.association.X, equal_nan=True)
    assert np.linalg.norm(a.X[sA, 3] - A[3]) < 1e-3


def test_only_a_young_track_settles():
    # the same ghost in the hypothesis of a track born more than settle_frames frames ago
    # stays (the rule is for discovery's joints; on a real detector re-solving every
    # track's poor joints took the neighbour's as often as its own)
    scene = _level_ring()
    good = list(scene)
    good[3] = np.stack([scene[1], scene[2]])
    core = None
    for t in range(3):                             # frames 0-2: both tracks born in frame 0
        core, r, _ = _resolve(2, good, stamp=t * 33_000_000, core=core, tracked=2 * (t > 0))
        assert sorted(r.ids.tolist()) == [0, 1]
    _, r, _ = _resolve(2, scene, stamp=3 * 33_000_000, core=core, tracked=2)   # 3 frames old
    assert r.settled == 0
    core, _, _ = _resolve(2, good, stamp=0)                                  # born in frame 0
    _, r, _ = _resolve(2, scene, stamp=33_000_000, core=core, tracked=2)     # 1 frame old
    assert r.settled == 1
