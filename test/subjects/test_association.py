"""Association across cameras and identities over time: subjects whose instance order is
shuffled in every camera and frame, checked against the ground truth that made them."""
import numpy as np
import pytest

from monet_ros.config import ConfigError
from monet_ros.geometry import triangulate
from monet_ros.geometry.units import rescale
from monet_ros.skeleton import load_skeleton
from monet_ros.subjects import AssociationConfig, associate
from monet_ros.subjects.tracking import SubjectTracker, TrackerConfig
from monet_ros.synth.rig import RigConfig, make_rig
from monet_ros.synth.subjects import (
    make_subjects,
    shuffled_instances,
    subjects_keypoints,
    subjects_occlusion,
)

FPS = 30.0
SKELETON = load_skeleton('human14')


@pytest.fixture(scope='module')
def crossing():
    """Two subjects over 120 frames around their closest approach (frames 0..119 hold
    it), 6 cameras, 1 px noise, shuffled instances."""
    times = np.arange(120) / FPS
    X = subjects_keypoints(SKELETON, 2, times)
    cams = make_rig(RigConfig(num_cameras=6))
    points, owner = shuffled_instances(X, cams, noise_px=1.0, seed=3)
    return times, X, cams, points, owner


def _owners(a, owner_t):
    """GT subject of each associated subject (S,), -2 if its instances disagree."""
    V = owner_t.shape[0]
    out = []
    for inst in a.instance:
        got = {int(owner_t[v, inst[v]]) for v in range(V) if inst[v] >= 0}
        out.append(got.pop() if len(got) == 1 else -2)
    return np.array(out)


def _run(times, points, cams, config=None, units='m', tracker_config=None):
    tracker = SubjectTracker(SKELETON.num_keypoints, tracker_config, units=units)
    frames = []
    for k, t in enumerate(times):
        a = associate(points[k], cams, config=config)
        frames.append((a, tracker.step(a.X, round(t * 1e9))))
    return frames, tracker


def test_the_subjects_pass_each_other(crossing):
    _, X, _, _, _ = crossing
    gap = np.linalg.norm(X[:, 0, :, :2].mean(1) - X[:, 1, :, :2].mean(1), axis=-1)
    assert gap.min() < 0.7 and gap.max() > 1.5        # they come close and part again


def test_shuffled_instances_associate_and_keep_their_identities(crossing):
    times, X, cams, points, owner = crossing
    frames, tracker = _run(times, points, cams)
    identity = {}                                    # GT subject -> track id
    for k, (a, ids) in enumerate(frames):
        assert a.X.shape == (2, SKELETON.num_keypoints, 3) and a.unmatched == 0
        gt = _owners(a, owner[k])
        assert sorted(gt.tolist()) == [0, 1], k       # every camera's instances right
        assert (a.instance >= 0).all()
        assert len(set(ids.tolist())) == 2 and (ids >= 0).all()   # never shared
        for s in range(2):
            # the same instances put in GT order and triangulated plainly (DLT)
            ref = triangulate(points[k, np.arange(len(cams)), a.instance[s]], cams)
            np.testing.assert_allclose(a.X[s], ref, atol=0.01)
            err = np.linalg.norm(a.X[s] - X[k, gt[s]], axis=-1)
            assert np.nanmax(err) < 0.03, (k, s)
            identity.setdefault(gt[s], ids[s])
            assert ids[s] == identity[gt[s]], f'identity switch at frame {k}'
    assert sorted(identity.values()) == [0, 1]
    assert tracker.births == 2 and tracker.deaths == 0


def test_subject_seen_by_two_of_four_cameras(crossing):
    times, X, _, _, _ = crossing
    cams = make_rig(RigConfig(num_cameras=4))
    seen = np.ones((len(times), 2, 4), bool)
    seen[:, 1, [2, 3]] = False     # subject 1 only in cam0 and cam1 (90 degrees apart)
    points, owner = shuffled_instances(X, cams, noise_px=1.0, seen=seen, seed=4)
    frames, _ = _run(times, points, cams)
    identity = {}
    for k, (a, ids) in enumerate(frames):
        gt = _owners(a, owner[k])
        assert sorted(gt.tolist()) == [0, 1], k
        s1 = int(np.flatnonzero(gt == 1)[0])
        np.testing.assert_array_equal(a.instance[s1] >= 0, [True, True, False, False])
        assert (a.instance[1 - s1] >= 0).all()
        err = np.linalg.norm(a.X[s1] - X[k, 1], axis=-1)
        assert np.nanmedian(err) < 0.03, k
        for s in range(2):
            assert identity.setdefault(gt[s], ids[s]) == ids[s], k


def test_birth_and_death(crossing):
    times, X, cams, _, _ = crossing
    seen = np.ones((len(times), 2, len(cams)), bool)
    seen[:30, 1] = False                              # subject 1 is born at frame 30
    seen[80:, 0] = False                              # subject 0 leaves at frame 80
    points, owner = shuffled_instances(X, cams, noise_px=1.0, seen=seen, seed=5)
    config = TrackerConfig(max_missed_s=0.2)
    tracker = SubjectTracker(SKELETON.num_keypoints, config)
    deaths = []
    ids_of = {0: set(), 1: set()}
    for k, t in enumerate(times):
        a = associate(points[k], cams)
        ids = tracker.step(a.X, round(t * 1e9))
        for g, i in zip(_owners(a, owner[k]), ids):
            ids_of[int(g)].add(int(i))
        deaths.append(tracker.deaths)
        assert len(a.X) == (1 if k < 30 or k >= 80 else 2), k
    assert ids_of == {0: {0}, 1: {1}}                 # one identity each, never shared
    assert tracker.births == 2
    deaths = np.array(deaths)
    # dies on the first frame more than 0.2 s after its last one (frame 79)
    first = 80 + int(np.floor(0.2 * FPS))
    assert deaths[first - 1] == 0 and deaths[first] == 1 and deaths[-1] == 1
    assert tracker.ids.tolist() == [1]


def test_a_rig_in_mm_gives_the_same_subjects(crossing):
    times, _, cams, points, _ = crossing
    mm = rescale(cams, 'mm')
    frames_m, _ = _run(times[:40], points, cams)
    frames_mm, _ = _run(times[:40], points, mm, units='mm')
    for (a, ids), (b, ids_mm) in zip(frames_m, frames_mm):
        np.testing.assert_array_equal(a.instance, b.instance)
        np.testing.assert_array_equal(ids, ids_mm)
        np.testing.assert_allclose(b.X, a.X * 1000, rtol=1e-6, atol=1e-6)


def test_bad_input_and_settings_name_the_field(crossing):
    _, _, cams, points, _ = crossing
    with pytest.raises(ValueError, match=r'points2d must have shape \(V=6'):
        associate(points[0, :3], cams)
    with pytest.raises(ValueError, match='scores must have shape'):
        associate(points[0], cams, scores=np.ones((6, 2)))
    with pytest.raises(ConfigError, match='threshold_px'):
        AssociationConfig(threshold_px=0)
    with pytest.raises(ConfigError, match='gate_mm'):
        TrackerConfig(gate_mm=-1)
    tracker = SubjectTracker(SKELETON.num_keypoints)
    tracker.step(np.zeros((0, 14, 3)), 10)
    with pytest.raises(ValueError, match='stamps must increase'):
        tracker.step(np.zeros((0, 14, 3)), 10)


def test_low_scores_are_left_out(crossing):
    """A keypoint below confidence_threshold counts as missing: scoring one subject's
    instances 0 in all but two cameras leaves it seen by those two."""
    _, X, cams, points, owner = crossing
    scores = np.ones(points.shape[1:4])
    low = (owner[0] == 1) & (np.arange(6)[:, None] >= 2)
    scores[low] = 0.05
    a = associate(points[0], cams, scores=scores)
    gt = _owners(a, owner[0])
    s1 = int(np.flatnonzero(gt == 1)[0])
    assert (a.instance[s1] >= 0).sum() == 2 and (a.instance[1 - s1] >= 0).all()



def test_three_subjects_hiding_each_other():
    """Three subjects, 8 cameras, keypoints hidden by any subject's limbs dropped (7-12 of
    14 left in some instances): in frames 27 and 103 two subjects line up with two facing
    cameras and a chance pair of their instances (one of each) agreed there before the
    repair step (module docstring, step 3) split it; every frame must give 3 subjects of
    one ground-truth subject each."""
    times = np.arange(120) / FPS
    cams = make_rig(RigConfig(num_cameras=8))
    X, hidden = subjects_occlusion(make_subjects(SKELETON, 3), times, cams)
    points, owner = shuffled_instances(X, cams, noise_px=1.0, seed=3, hidden=hidden)
    for k in range(len(times)):
        a = associate(points[k], cams)
        assert sorted(_owners(a, owner[k]).tolist()) == [0, 1, 2], k


def test_frames_without_a_subject(crossing):
    _, _, cams, points, _ = crossing
    a = associate(np.full(points.shape[1:], np.nan), cams)
    assert a.X.shape == (0, 14, 3) and a.instances == 0 and a.unmatched == 0
    one = np.full(points.shape[1:], np.nan)
    one[2] = points[0, 2]                                 # only cam2 sees anyone
    a = associate(one, cams)
    assert len(a.X) == 0 and a.instances == 2 and a.unmatched == 2
    tracker = SubjectTracker(SKELETON.num_keypoints)
    assert tracker.step(a.X, 1).shape == (0,) and tracker.births == 0


def test_a_joint_unseen_longer_than_max_missed_is_restarted_not_extrapolated():
    # a subject of 4 keypoints walking at 1 m/s along x; its keypoint 3 (a hand) swings
    # forward at 4 m/s for 10 frames, then is not triangulated for 1 s (30 frames, more
    # than max_missed_s 0.5 s) and comes back beside the body. Its last velocity carried on
    # would put it ~3 m ahead and the subject's mean distance past the 400 mm gate: a new
    # identity. Unstarted after 0.5 s unseen, it is left out and started again.
    dt = 1 / 30
    body = np.array([[0.0, 0, 1.6], [0.0, 0, 1.3], [0.0, 0, 1.0], [0.3, 0, 1.0]])
    tracker = SubjectTracker(4)
    config = tracker.config
    stamp = lambda t: int(round(t * dt * 1e9))                        # noqa: E731
    X = body.copy()
    for t in range(10):
        X = body + [t * dt * 1.0, 0, 0]
        X[3, 0] = 0.3 + t * dt * 4.0
        assert tracker.step(X[None], stamp(t)).tolist() == [0]
    v_hand = tracker.v[0, 3, 0]
    assert v_hand > 2.0                                   # the swing is in the track
    for t in range(10, 40):
        X = body + [t * dt * 1.0, 0, 0]
        X[3] = np.nan
        assert tracker.step(X[None], stamp(t)).tolist() == [0]
        if (t - 9) * dt > config.max_missed_s:
            assert np.isnan(tracker.predicted(stamp(t + 1))[0, 3]).all()
    X = body + [40 * dt * 1.0, 0, 0]
    # independently: the hand's last position carried on at its last velocity to frame 40
    # lies more than 4 gates from the hand: alone it would take the mean of 4 joints past
    # the gate
    carried = 0.3 + 9 * dt * 4.0 + v_hand * 31 * dt
    assert abs(X[3, 0] - carried) > 4 * config.gate_mm / 1000
    assert tracker.step(X[None], stamp(40)).tolist() == [0]        # the same identity
    assert tracker.births == 1 and tracker.started[0].all()       # the hand started again


def test_a_frame_of_one_camera_gives_no_subject(crossing):
    # the live fusion can get an instant with one view (the others late): its two
    # instances are matched in no other camera, counted, and no error is raised (an empty
    # pair list once came out as a float index)
    _, _, cams, points, _ = crossing
    a = associate(points[0, 2:3], cams[2:3])
    assert len(a.X) == 0 and a.instances == 2 and a.unmatched == 2


def test_leaving_out_views_triangulates_from_the_others(crossing):
    """leave_out_views: a keypoint with a view left out is the triangulation of its other
    detections (here: the association's own triangulation of the same points with that
    view's score 0); the others are untouched; a drop of the wrong shape names it."""
    from monet_ros.geometry import triangulate_robust
    from monet_ros.subjects.association import leave_out_views

    _, _, cams, points, _ = crossing
    a = associate(points[0], cams)
    before = {k: getattr(a, k).copy() for k in ('X', 'inliers', 'score', 'points2d')}
    S, V, C = a.inliers.shape
    drop = np.zeros((S, V, C), bool)
    drop[0, 1, 3] = drop[0, 2, 3] = True          # subject 0's keypoint 3 loses 2 views
    drop[1, :, 5] = True                          # subject 1's keypoint 5 loses all
    seen = a.scores2d > 0
    expected_count = int((drop & seen).sum())
    p, w = a.points2d[0, :, 3].copy(), a.scores2d[0, :, 3].copy()
    w[[1, 2]] = 0.0
    expected, inl = triangulate_robust(np.where(w[:, None] > 0, p, np.nan)[:, None], cams,
                                       w[:, None])
    assert leave_out_views(a, cams, drop) == expected_count
    assert np.allclose(a.X[0, 3], expected[0]) and not a.inliers[0, [1, 2], 3].any()
    assert np.isnan(a.points2d[0, [1, 2], 3]).all()
    assert np.isnan(a.X[1, 5]).all() and np.isnan(a.score[1, 5])   # no view left
    untouched = np.ones((S, C), bool)
    untouched[0, 3] = untouched[1, 5] = False
    assert np.array_equal(a.X[untouched], before['X'][untouched])
    assert np.array_equal(a.inliers.transpose(0, 2, 1)[untouched],
                          before['inliers'].transpose(0, 2, 1)[untouched])
    assert leave_out_views(a, cams, np.zeros((S, V, C), bool)) == 0
    with pytest.raises(ValueError, match='drop must have shape'):
        leave_out_views(a, cams, np.zeros((S, V)))


def _random_instances(rng, M, V, C):
    """M instances on V cameras (each camera at least once when M >= V), C keypoints
    each, a third of them missing: (ideal (M, C, 2) px, present (M, C), view (M,))."""
    view = np.concatenate([np.arange(min(M, V)), rng.integers(0, V, max(0, M - V))])
    ideal = rng.uniform(0, 640, (M, C, 2))
    present = rng.random((M, C)) > 0.33
    ideal[~present] = np.nan
    return ideal, present, view


def test_pair_costs_are_median_symmetric_epipolar_distances_from_opencv():
    """pair_costs (compiled) against OpenCV: cv2.computeCorrespondEpilines gives each
    point's epipolar line in the other image (normalised: a^2 + b^2 = 1), the distance of
    the other point to it; the cost is np.median over the keypoints both see of the mean
    of the two distances; inf for one camera, itself or < min_common common keypoints."""
    import cv2

    from monet_ros.subjects.association import pair_costs, pair_fundamentals

    rng = np.random.default_rng(11)
    cams = make_rig(RigConfig(num_cameras=5))
    F = pair_fundamentals(cams)
    for M, C, min_common in ((9, 14, 3), (12, 7, 1), (6, 4, 4)):
        ideal, present, view = _random_instances(rng, M, len(cams), C)
        cost, common = pair_costs(ideal, present, view, F, min_common)
        for a in range(M):
            for b in range(M):
                both = present[a] & present[b]
                assert common[a, b] == both.sum()
                if a == b or view[a] == view[b] or both.sum() < min_common:
                    assert cost[a, b] == np.inf
                    continue
                fab = F[view[a], view[b]]                     # x_b^T F x_a = 0
                pa = ideal[a, both].reshape(-1, 1, 2)
                pb = ideal[b, both].reshape(-1, 1, 2)
                in_b = cv2.computeCorrespondEpilines(pa, 1, fab).reshape(-1, 3)
                in_a = cv2.computeCorrespondEpilines(pb, 2, fab).reshape(-1, 3)
                d_b = np.abs((in_b[:, :2] * pb[:, 0]).sum(-1) + in_b[:, 2])
                d_a = np.abs((in_a[:, :2] * pa[:, 0]).sum(-1) + in_a[:, 2])
                np.testing.assert_allclose(cost[a, b], np.median(0.5 * (d_a + d_b)),
                                           rtol=1e-9, atol=1e-9)


def _greedy_reference(cost, view, threshold_px, strong):
    """Step 2 of the association's clustering, written plainly in Python (lists and
    sets): candidate pairs a < b with cost <= threshold, strong first, then by cost
    (ties: row-major order), merged when the clusters share no camera and the mean of the
    finite costs between their members is <= threshold."""
    M = len(view)
    pairs = [(not strong[a, b], cost[a, b], a, b) for a in range(M) for b in range(a + 1, M)
             if cost[a, b] <= threshold_px]
    pairs.sort(key=lambda p: (p[0], p[1]))             # stable: row-major among ties
    cluster = {m: {m} for m in range(M)}
    for _, _, a, b in pairs:
        ca, cb = cluster[a], cluster[b]
        if ca is cb or {view[m] for m in ca} & {view[m] for m in cb}:
            continue
        linked = [cost[m, n] for m in ca for n in cb if np.isfinite(cost[m, n])]
        if sum(linked) > threshold_px * len(linked):
            continue
        ca |= cb
        for m in cb:
            cluster[m] = ca
    return [min(cluster[m]) for m in range(M)]


def test_clustering_is_the_greedy_rule_written_plainly():
    """The compiled clustering step against _greedy_reference on random symmetric costs
    (some infinite, some ties, strong and weak pairs): the same partition."""
    from monet_ros.subjects.association import _merge_clusters

    rng = np.random.default_rng(5)
    for trial in range(300):
        M, V = int(rng.integers(2, 25)), int(rng.integers(2, 9))
        view = rng.integers(0, V, M)
        cost = np.round(rng.uniform(0, 30, (M, M)), 0 if trial % 3 == 0 else 6)  # ties
        cost[rng.random((M, M)) < 0.2] = np.inf
        cost = np.minimum(cost, cost.T)
        cost[view[:, None] == view[None]] = np.inf
        strong = rng.random((M, M)) < 0.5
        strong = strong & strong.T
        got = _merge_clusters(cost, view.astype(np.int64), V, 15.0, strong)
        want = _greedy_reference(cost, view, 15.0, strong)
        # the same partition (labels may name a cluster by another member)
        first = {}
        assert [first.setdefault(g, w) for g, w in zip(got.tolist(), want)] == want
        assert len(set(got.tolist())) == len(set(want))


def test_degenerate_epipolar_geometry_gives_no_cost_not_an_error():
    """Two cameras with one centre have no epipolar geometry (F = 0): every line is
    degenerate, the distances are not finite, and the pair has no cost (inf), as numpy's
    division by zero would give; the compiled loop raises nothing."""
    from monet_ros.subjects.association import pair_costs

    rng = np.random.default_rng(1)
    ideal, present, view = _random_instances(rng, 6, 3, 5)
    present[:] = True
    ideal = rng.uniform(0, 640, ideal.shape)
    cost, common = pair_costs(ideal, present, view, np.zeros((3, 3, 3, 3)), 1)
    assert np.isinf(cost).all() and (common == 5).all()


def test_compiled_steps_refuse_indices_they_would_not_check():
    """The compiled loops do not check indices: their callers refuse a camera index
    outside the rig and shapes that do not match, naming what."""
    from monet_ros.subjects.association import cluster_instances, pair_costs

    ideal, present, view = np.zeros((3, 4, 2)), np.ones((3, 4), bool), np.array([0, 1, 2])
    F = np.zeros((2, 2, 3, 3))
    with pytest.raises(ValueError, match=r'camera indices must be in \[0, 2\), got 0 to 2'):
        pair_costs(ideal, present, view, F, 1)
    with pytest.raises(ValueError, match='must be'):
        pair_costs(ideal[:2], present, view, F, 1)
    with pytest.raises(ValueError, match=r'camera indices must be in \[0, 2\)'):
        cluster_instances(np.zeros((3, 3)), view, 2, 15.0)
    with pytest.raises(ValueError, match='must be \\(M, M\\)'):
        cluster_instances(np.zeros((2, 2)), view, 3, 15.0)
    with pytest.raises(ValueError, match='camera indices'):
        cluster_instances(np.zeros((3, 3)), np.array([0, -1, 1]), 3, 15.0)


def test_pair_costs_refuse_min_common_below_one():
    """min_common < 1 would ask for the median of no keypoints (AssociationConfig refuses
    it too): refused by name."""
    from monet_ros.subjects.association import pair_costs

    with pytest.raises(ValueError, match='min_common must be >= 1, got 0'):
        pair_costs(np.zeros((2, 0, 2)), np.zeros((2, 0), bool), np.array([0, 1]),
                   np.zeros((2, 2, 3, 3)), 0)
