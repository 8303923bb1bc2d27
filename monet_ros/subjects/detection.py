"""Several subjects through the detector, one frame at a time (no ROS): the core of
`monet process --subjects N`.

Algorithm, per synchronized frame (stamps increasing):

1. Hypotheses: the SubjectTracker's predicted joints (its Kalman prediction to the
   frame's stamp) of the tracks matched in at least one of the last `crop_missed` frames,
   at most N of them, the most recently matched first (then the oldest identity). A track
   missed longer (its crops decoded nothing it matched, or a body another crop decoded
   too) lives on in the tracker until max_missed_s, so a subject found again within the
   gate (grown with the time it was missed: subjects.tracking step 2) keeps its identity,
   but it gets no crops: its prediction drifts by its velocity
   and its crops would only decode a neighbour (a duplicate) or nothing. Discovery, when
   fewer than N tracks get crops (at the start, and after a track was missed):
   a. one full-frame detection per view; the `candidates` highest local maxima of every
      keypoint's map (models.decode_heatmap_peaks, at least the confidence threshold).
      With discovery_tiles n >= 1 (SubjectsStep, `monet process`; 2 by default) a view
      whose whole frame would go into the network shrunk more than TILE_SHRINK (2) times
      is detected as square tiles, n along its shorter side, neighbours overlapping by
      half (tile_boxes), and its candidates are the `candidates` highest peaks over its
      tiles, a peak within half the association's threshold_px of a higher one dropped
      (the same blob in two tiles: merge_peaks). Why: the detector is trained on crops
      around one subject; a whole 320 x 240 frame goes through a 128 px input at 0.4 of
      the source scale (subject crops at 0.5-1.0: shrunk at most about 2 times), where a
      detector trained on two subjects answered one of two subjects 1 m apart with a
      median peak of 0.16 at its joints (the other 0.36) and discovery never found it in
      30 runs (subject 1 missed in the first 35 frames, a ghost of subject 0 tracked
      instead: 2 identity switches; tiles of 160 px: found in frame 0;
      bench/results/subjects_process.md, change 9). Live, the detector nodes cut the same
      maps (discovery_boxes) and publish them as discovery crop slots, and the fusion node
      merges them as here (live_frame).
   b. per keypoint, each (view, peak) is a one-keypoint instance; subjects.association.
      associate clusters them across views (epipolar distance, at most one per camera,
      >= min_views) and triangulates each cluster robustly: 3D points of that keypoint;
   c. a point within the tracker's gate (gate_mm) of a cropped track's predicted joint
      of the same keypoint belongs to that track and is dropped;
   d. the rest are grouped into subjects by constrained single linkage (Kruskal order):
      every pair of points of two different keypoints closer than link_mm, shortest
      first, merges their two groups unless the groups share a keypoint (a subject has
      one point per keypoint: two subjects, each linked by its own shorter pairs,
      never merge through a pair between them). Geometry alone cannot tell keypoints of
      two subjects apart where they are closer than a subject's own adjacent keypoints
      (bodies in contact): such a frame can start a mixed hypothesis;
   e. groups with >= the tracker's min_keypoints points are new hypotheses, the most
      keypoints (then the most views) first, until N hypotheses exist; a group whose
      keypoints lie within the tracker's gate_mm (median over the keypoints both have) of
      a hypothesis taken before it in this frame is a second group of that body (a
      keypoint seen twice, by two tiles or two weak peaks a few cm apart, which 1d keeps
      in separate groups): left out, counted as `repeated` (repeated_body). Otherwise
      both became tracks of one body, and the second kept an identity while the
      subject it missed went untracked (measured: one subject's two groups at frame 0,
      3 subjects, bench/results/subjects_process.md, change 9).
2. Crops: per view, one crop per hypothesis, the single-subject crop rule's box
   (crop_rule.subject_boxes with the TrackedRule's margin, min_points and trim) around its
   joints projected into that view; a view where too few joints project has no crop for
   it. All crops of the frame go through the detector in one batch.
3. One instance per crop: per keypoint, among the `crop_peaks` highest local maxima of the
   crop's map (>= the confidence threshold), the one nearest the hypothesis' joint
   projected into the view (the highest where the joint is unknown); source pixels and
   the peak value as its score. So a crop showing two subjects decodes the one it was cut
   for. With rival_peaks (on by default), a chosen peak that lies nearer another
   hypothesis' joint of the same keypoint (projected into the view) than its own is left
   out: the joint is hidden in that view and the peak is the neighbour's.
4. The instances of all views (slot h = hypothesis h's crop) go through associate (the
   instance order is not trusted) and are triangulated per subject. With foreign_views
   (on by default), a subject's view whose instance came from the crop of another
   hypothesis than its own (the hypothesis whose crops give most of its instances, if
   one alone does), a hypothesis with a predicted body (a track or a discovered
   subject; not a live crop of unknown joints), is left out of the triangulation of
   each of its keypoints for which at least min_views of the subject's other views
   remain (counted as `foreign`; association.leave_out_views). Why: that crop was cut
   around the other hypothesis and took, per keypoint, the peak nearest its predicted
   joint (with rival_peaks: nearer it than any other hypothesis' joint, this subject's
   included; its highest peak where the joint was unknown), so its instance is that
   subject's decode; the epipolar clustering put it here because two subjects within
   about 1 m lie on nearly the same epipolar lines in some camera pairs (measured on 2
   synthetic subjects passing, 84 of 300 frames within 1 m: 470 of the 822 joints' 2D
   points that lay nearer the other subject's same joint than this subject's came from
   such foreign instances; bench/results/subjects_process.md, change 8). The rule is
   ours, from that measurement: it keeps the association's choice of which subject
   each instance joins (leaving a subject only its own crops was worse: a capturing
   crop's instance then stays) and only stops a neighbour's decode from pulling this
   subject's 3D. A subject whose joints' median score (heatmap peak value, mean over
   the joint's inlier views) is below min_score is weak: dropped, counted (the
   detector's peaks on a body are near 1; a hypothesis discovered from secondary
   full-frame peaks, floor or background, gets crops that decode 14 joints of scores
   0.15-0.5 and 2-9 px reprojection error, a ghost that would be tracked for as long
   as its crops keep decoding it). A subject whose mean joint distance to a subject
   seen by more cameras (association's order) is below duplicate_mm is the same body
   decoded by two hypotheses' crops: dropped, counted.
   4b. Settling (settle_frames >= 1): for a subject of a hypothesis discovered in this
   frame or of a track born at most settle_frames frames ago, a joint whose mean
   reprojection error (px, over its inlier views) exceeds both settle_px and
   settle_ratio times the median of its subject's joints' errors, or that has only
   min_views (2) inlier views where the subject's median joint has more than twice as
   many (two rays that agree epipolarly meet with no residual), is solved again from
   all the candidate peaks (step 3's crop_peaks) of the subject's crops, by
   geometry.select_candidates (the pair of peaks of two views whose 3D point most of
   the views' peaks support within that tolerance, the stronger peaks first; the same
   rule as the one-subject fusion's), a peak that another subject took for that keypoint
   in that view (within half the association's threshold_px) left out; the joint
   triangulated from the supporting peaks replaces the old one where it has at least
   min_views inlier views and a smaller mean reprojection error, or more inlier views
   with the error within the tolerance (counted as `settled`). Why: discovery associates
   each keypoint's full-frame peaks across views by epipolar distance alone (step 1b),
   and where the subjects stand near the plane of the
   camera centres every epipolar line is nearly the same image line, so a joint can be
   triangulated from two subjects' peaks (a ghost: the start of bench/subjects_live.py
   with 2 subjects, a right shoulder 633 mm off from peaks of the two subjects in two
   views), and the crops then keep it (each takes the peak nearest the ghost, step 3):
   it re-triangulated at 5-14 px for 7 frames while the other joints were at about
   1 px. Only a young track's joints: applied to every track (`monet process` on a real
   detector, where a joint that fits the body worse is often a passing neighbour's limb
   or a weak map), the re-solve took the neighbour's joint as often as its own and
   cost identity switches (bench/results/subjects_live.md, 2026-12-05 11:05-12:00 UTC).
5. N subjects: first, per hypothesis in order (tracks first), the subject holding most
   of that hypothesis' crop instances, if any is left (a subject seen by fewer cameras,
   e.g. one cut by the image borders, is not pushed out by a neighbour's extra or mixed
   subject seen by more); then the rest, most cameras first. The others are counted as
   `extra`. A keypoint
   of two of them closer than duplicate_mm is one body part decoded by two subjects'
   crops (a joint captured from the neighbour: the capturing track's prediction follows
   it, so its next crop would decode the neighbour's joint again): the subject whose
   joint lies farther from its own other joints (their median distance) loses it (NaN,
   counted as `shared`), the other keeps it. Then each subject's joints are grouped by
   single linkage within link_mm (discovery's linkage, step 1d); joints in a group smaller
   than the subject's largest are not linked to its body: a ghost (triangulated from
   peaks of different subjects in different views) or a limb taken from the neighbour,
   whose track's prediction would keep its crops' peaks there. They go too (NaN, counted
   as `detached`).
6. They go to the SubjectTracker (max_tracks N): Hungarian assignment to the tracks'
   predicted bodies (gated), births (while fewer than N identities are alive; a subject
   no track takes with N alive is left untracked), deaths (subjects.tracking). Its
   identities are the output's. A
   joint dropped in step 5 is restarted in its track (unstarted: no prediction), so the
   next frame's crops take their highest peak for it (step 3): the crop is centred on
   the track's own body.

Units: the rig's (the cameras'); link_mm, duplicate_mm and the tracker's settings are
physical (mm) and converted. Full-frame decodes cost one extra forward of V images, only
in frames that discover.
"""
from dataclasses import dataclass

import numpy as np

from monet_ros.config import setting, validate_config
from monet_ros.crop_rule import TrackedRule, subject_boxes
from monet_ros.fusion import MAX_PEAKS_PER_VIEW, crop_scales, heat_to_source_points
from monet_ros.geometry import project_views, stack_cameras
from monet_ros.geometry.units import from_mm
from monet_ros.subjects.association import (
    Association,
    AssociationConfig,
    associate,
    leave_out_views,
)
from monet_ros.subjects.tracking import SubjectTracker


@dataclass(frozen=True)
class SubjectsConfig:
    """Settings of the detector's several-subject step (validated; errors name the
    field). The association and the tracker have their own configs."""
    subjects: int = setting(1, 'most subjects tracked and written per frame', minimum=1)
    candidates: int = setting(
        3, 'discovery: heatmap peaks per view and keypoint of the full-frame detection',
        minimum=1, maximum=2 * MAX_PEAKS_PER_VIEW)
    link_mm: float = setting(
        600.0, 'discovery: largest distance (mm) between two keypoints of one subject '
        'linked into a group (adjacent joints are closer)', minimum=0.0,
        exclusive_minimum=True)
    crop_peaks: int = setting(
        3, "per-subject crops: peaks per keypoint among which the one nearest the subject's "
        'predicted joint is taken', minimum=1, maximum=2 * MAX_PEAKS_PER_VIEW)
    duplicate_mm: float = setting(
        100.0, 'mean joint distance (mm) below which two associated subjects are one body; '
        "also the distance below which two subjects' same keypoint is one body part (kept "
        'by one)', minimum=0.0)
    crop_missed: int = setting(
        1, 'per-subject crops: a track missed in this many consecutive frames gets no crops '
        '(discovery looks for its subject again)', minimum=1)
    min_score: float = setting(
        0.4, "a subject whose joints' median score (heatmap peak value, mean over its inlier "
        'views) is below this is not a subject (a ghost triangulated from weak peaks) and '
        'is not tracked', minimum=0.0)
    rival_peaks: bool = setting(
        True, "per-subject crops: leave out a keypoint's chosen peak when it lies nearer "
        "another subject's predicted joint of that keypoint than its own (a joint hidden "
        "in the view would otherwise take the neighbour's peak)")
    foreign_views: bool = setting(
        True, "leave out of a subject's triangulation the views whose instance came from "
        "another subject's crop (the peaks nearest that subject's predicted joints), where "
        'at least min_views other views remain')

    settle_frames: int = setting(
        3, "a track's first frames after its birth (and a subject discovered this frame) "
        'in which a joint that fits its subject much worse than its other joints is solved '
        "again from its crops' peaks by consistency (0: never)", minimum=0)
    settle_ratio: float = setting(
        5.0, 'settling: a joint is solved again when its mean reprojection error exceeds this '
        "times the median of its subject's joints' errors (and settle_px)", minimum=1.0)
    settle_px: float = setting(
        5.0, 'settling: a joint is solved again only when its mean reprojection error (px) '
        'exceeds this (and settle_ratio times the median)', minimum=0.0,
        exclusive_minimum=True)

    discovery_tiles: int = setting(
        2, 'discovery: the full-frame detection of a view whose whole frame the network '
        'input would shrink more than 2 times, as square tiles, this many along the shorter '
        'image side, neighbours overlapping by half (0: always the whole frame); live, the '
        "detector and fusion nodes' discovery_tiles must be equal (the discovery crop "
        'slots)', minimum=0)

    def __post_init__(self):
        validate_config(self)


@dataclass
class FrameSubjects:
    """One frame's result. association: the subjects.association.Association of the crop
    instances (all its subjects, duplicates included); keep (K,) int: the indices of the
    subjects given to the tracker (at most N, duplicates left out); ids (K,) their
    identities (-1: untracked: too few keypoints, or N identities alive and none took it);
    and the counts: hypotheses (crops per view; tracked: those of tracks), discovered
    (new hypotheses from the full frame; -1: no discovery this frame), points
    (discovery's 3D keypoint points), explained (of those, near a cropped track's joint),
    loose (in groups with too few keypoints, or
    beyond N: left out), repeated (in a second group of a body discovered, step 1e),
    crops (detector crops), duplicates, extra (subjects beyond N),
    shared (joints dropped as decoded by two subjects, step 5), detached (joints dropped as
    not linked within link_mm to their subject's largest group of joints, step 5),
    foreign (views left out of a subject's keypoints as another hypothesis' crop's, step
    4), settled (joints solved again while their track settles, step 4b)."""
    association: object
    keep: np.ndarray
    ids: np.ndarray
    hypotheses: int
    discovered: int
    crops: int
    duplicates: int
    extra: int
    points: int = 0
    explained: int = 0
    loose: int = 0
    tracked: int = 0
    shared: int = 0
    detached: int = 0
    weak: int = 0
    foreign: int = 0
    repeated: int = 0
    settled: int = 0


def weak_subjects(score, min_score):
    """Subjects not supported by the detector (module docstring step 4): score (S, C) each
    subject's per-joint score (NaN: joint not triangulated), min_score: the least median.
    -> (S,) bool, True where the median of the subject's finite scores is below min_score
    (or it has none)."""
    score = np.asarray(score, np.float64)
    finite = np.isfinite(score)
    some = finite.any(-1)
    median = np.full(len(score), -np.inf)
    if some.any():
        median[some] = np.nanmedian(np.where(finite[some], score[some], np.nan), axis=-1)
    return median < min_score


def subject_keypoints(frame):
    """The tracked subjects of a FrameSubjects, by identity: ids (K,) increasing, X (K, C, 3)
    (rig units, NaN: not triangulated), score (K, C) (0: none), error (K, C) mean
    reprojection error (px) over each keypoint's inlier views (NaN: none), views (K, C)
    int inlier views. Subjects without an identity (-1) are left out."""
    a = frame.association
    tracked = frame.ids >= 0
    order = np.argsort(frame.ids[tracked], kind='stable')
    rows = frame.keep[tracked][order]
    views = a.inliers[rows].sum(1)                                        # (K, C)
    with np.errstate(invalid='ignore', divide='ignore'):
        error = np.where(a.inliers[rows], a.view_errors[rows], 0.0).sum(1) / views
    return (frame.ids[tracked][order], a.X[rows], np.nan_to_num(a.score[rows]), error,
            views)


def group_points(points, keypoint, views, link):
    """Constrained single linkage of 3D points (module docstring, step 1d).

    points (P, 3), keypoint (P,) int, views (P,) int (cameras of each point), link: the
    largest linking distance (rig units). -> list of index arrays, one per group, the
    groups with the most keypoints (then the most views) first."""
    P = len(points)
    if not P:
        return []
    d = np.linalg.norm(points[:, None] - points[None], axis=-1)
    a, b = np.nonzero(np.triu((d <= link) & (keypoint[:, None] != keypoint[None]), 1))
    label = np.arange(P)
    masks = [{int(k)} for k in keypoint]
    order = np.argsort(d[a, b], kind='stable')                       # shortest first
    for i, j in zip(a[order].tolist(), b[order].tolist()):
        la, lb = label[i], label[j]
        if la == lb or masks[la] & masks[lb]:
            continue
        label[label == lb] = la
        masks[la] |= masks[lb]
    groups = [np.flatnonzero(label == g) for g in np.unique(label)]
    return sorted(groups, key=lambda g: (-len(g), -int(views[g].sum()), int(g[0])))


# discovery tiles a view whose whole frame goes into the network shrunk more than this
# (module docstring step 1a)
TILE_SHRINK = 2.0


def tile_boxes(width, height, tiles):
    """Square discovery tiles of a width x height image (module docstring step 1a):
    `tiles` along the shorter side, each of side shorter / (1 + (tiles - 1) / 2), so
    neighbours overlap by half; along the longer side as many at the same step (the last
    one flush with the edge). -> (T, 4) boxes (x0, y0, x1, y1, pixel edges)."""
    side = min(width, height) / (1 + (tiles - 1) / 2)
    step = side / 2

    def starts(length):
        n = max(1, int(np.ceil((length - side) / step - 1e-9)) + 1)
        return np.minimum(np.arange(n) * step, length - side)

    x, y = np.meshgrid(starts(width), starts(height))
    x, y = x.ravel(), y.ravel()
    return np.stack([x, y, x + side, y + side], axis=-1)


def discovery_slots(width, height, tiles):
    """The most discovery maps of a width x height view with discovery_tiles `tiles` (the
    live discovery crop slots of a camera): its tile count (tile_boxes), 1 (the whole
    frame) with tiles 0. -> int >= 1."""
    return len(tile_boxes(width, height, tiles)) if tiles else 1


def discovery_tiles_for(width, height, slots):
    """The discovery_tiles values that give a width x height view `slots` discovery maps
    (the inverse of discovery_slots: a detector's value read from the crop slots it
    publishes). -> sorted list of int >= 0, empty when none does (e.g. 3 for a square
    view); both 0 and 1 give 1 slot on a square view."""
    out, tiles = [], 0
    while tiles <= max(int(slots), 1) and discovery_slots(width, height, tiles) <= slots:
        if discovery_slots(width, height, tiles) == slots:
            out.append(tiles)
        tiles += 1
    return out


def discovery_boxes(detector, cameras, tiles):
    """The boxes of discovery's full-frame detection (module docstring step 1a), one list
    entry per view of `cameras`: (T_v, 4) pixel edges, as detector.predict takes them with
    keep_aspect False (already fitted to the network's aspect): the view's tiles
    (tile_boxes, `tiles` along its shorter side) where its whole frame would go into the
    network shrunk more than TILE_SHRINK times and tiles >= 1, else its whole frame
    (detector.boxes_for: padded to the aspect). detector: a models.Detector (its
    input_size and boxes_for). One implementation for `monet process` (SubjectsStep) and
    the live detector node's discovery slots."""
    full = detector.boxes_for(cameras)                                   # (V, 4) whole frames
    shrink = (full[:, 2] - full[:, 0]) / detector.input_size[1]
    out = []
    for v, (camera, s) in enumerate(zip(cameras, shrink)):
        if tiles and s > TILE_SHRINK:
            out.append(detector.boxes_for([camera] * discovery_slots(
                camera.width, camera.height, tiles), tile_boxes(camera.width, camera.height,
                                                                tiles)))
        else:
            out.append(full[v:v + 1])
    return out


def merge_peaks(pts, conf, views, num_views, k, radius):
    """One view's peaks from its tiles' maps (module docstring step 1a): pts (M, C, k', 2)
    source px (NaN: none) and conf (M, C, k') of M maps, views (M,) the view of each;
    per view and keypoint, the k highest peaks over its maps, a peak within `radius` px of
    a higher one kept already left out (the same blob seen by two overlapping tiles).
    -> pts (num_views, C, k, 2) (NaN: none), conf (num_views, C, k) (0 there)."""
    M, C, kk = conf.shape
    out_p = np.full((num_views, C, k, 2), np.nan)
    out_c = np.zeros((num_views, C, k))
    if not M:
        return out_p, out_c
    order = np.argsort(views, kind='stable')
    counts = np.bincount(views, minlength=num_views)
    n = int(counts.max()) * kk                                    # candidates per view
    P = np.full((num_views, C, n, 2), np.nan)
    Q = np.full((num_views, C, n), -np.inf)
    slot = np.arange(M) - np.searchsorted(views[order], views[order])   # map within view
    rows = views[order]
    for j in range(kk):                                  # k' candidates of each map
        P[rows, :, slot * kk + j] = pts[order, :, j]
        Q[rows, :, slot * kk + j] = np.where(np.isfinite(pts[order, :, j]).all(-1),
                                             conf[order, :, j], -np.inf)
    rank = np.argsort(-Q, axis=-1, kind='stable')
    P = np.take_along_axis(P, rank[..., None], axis=2)
    Q = np.take_along_axis(Q, rank, axis=2)
    keep = np.zeros(Q.shape, bool)
    for i in range(n):                        # greedy: the strongest first, in order
        d = np.linalg.norm(P[:, :, :i] - P[:, :, i:i + 1], axis=-1)          # (V, C, i)
        near = (keep[:, :, :i] & (d <= radius)).any(-1)
        keep[:, :, i] = np.isfinite(Q[:, :, i]) & ~near & (keep[:, :, :i].sum(-1) < k)
    place = np.cumsum(keep, axis=-1) - 1
    v, c, i = np.nonzero(keep)
    out_p[v, c, place[v, c, i]] = P[v, c, i]
    out_c[v, c, place[v, c, i]] = Q[v, c, i]
    return out_p, out_c


def repeated_body(X, found, near):
    """Whether a discovered group X (C, 3) (NaN: keypoint not in it) is a second group of
    the body of an earlier hypothesis (module docstring, step 1e): found, the hypotheses
    taken so far (each (C, 3)); near: the largest median distance (rig units), over the
    keypoints both have, of a group from a hypothesis of the same body. -> bool."""
    if not len(found):
        return False
    with np.errstate(invalid='ignore'):
        d = np.linalg.norm(np.asarray(found, np.float64) - X, axis=-1)     # (H, C)
    both = np.isfinite(d)
    some = both.any(-1)
    if not some.any():
        return False
    median = np.nanmedian(np.where(both[some], d[some], np.nan), axis=-1)
    return bool((median <= near).any())


def shared_joints(X, near):
    """Joints decoded twice (module docstring, step 5): X (K, C, 3) the subjects' joints,
    near: the largest distance (rig units) of two subjects' same keypoint that is one body
    part. -> (K, C) bool, True where the joint goes: of two subjects whose keypoint c lies
    within `near`, the one whose joint is farther (median) from its own other joints loses
    it (tie: the later subject)."""
    K, C = X.shape[:2]
    drop = np.zeros((K, C), bool)
    if K < 2:
        return drop
    with np.errstate(invalid='ignore'):
        own = np.linalg.norm(X[:, :, None] - X[:, None], axis=-1)         # (K, C, C)
        own[:, np.arange(C), np.arange(C)] = np.nan
        fit = np.full((K, C), np.inf)
        some = np.isfinite(own).any(-1)
        fit[some] = np.nanmedian(own[some], axis=-1)
        pair = np.linalg.norm(X[:, None] - X[None], axis=-1) <= near       # (K, K, C)
    s, t, c = np.nonzero(np.triu(np.ones((K, K), bool), 1)[..., None] & pair)
    loser = np.where(fit[t, c] >= fit[s, c], t, s)
    drop[loser, c] = True
    return drop


def claimed_first(instance, keep, H):
    """The subjects `keep` (K,) (indices into instance's rows, in association order:
    most cameras first) reordered as module docstring step 5: per hypothesis h = 0..H-1,
    the not yet claimed subject with the most instances from h's crops (ties: the earlier)
    comes first, in hypothesis order; then the unclaimed ones in their order. instance
    (S, V) int: each subject's crop slot (hypothesis) per view, -1 = none. -> (K,) int."""
    keep = np.asarray(keep, np.int64)
    if not len(keep) or not H:
        return keep
    count = (instance[keep][:, :, None] == np.arange(H)).sum(1)           # (K, H)
    claimed = np.zeros(len(keep), bool)
    first = []
    for h in range(H):                                  # a few hypotheses: at most N + new
        free = np.where(claimed, -1, count[:, h])
        k = int(np.argmax(free))
        if free[k] > 0:
            claimed[k] = True
            first.append(k)
    return np.concatenate([keep[first], keep[~claimed]])


def detached_joints(X, link):
    """Joints linked to no larger part of their subject's body (module docstring, step 5):
    X (K, C, 3) the subjects' joints (NaN: none), link: the largest distance (rig units) of
    two linked joints of one body. The triangulated joints of a subject fall into groups by
    single linkage within `link` (discovery's linkage, step 1d); a joint goes when its
    group has fewer joints than the subject's largest group (two largest groups of equal
    size both stay: nothing tells which is the body). -> (K, C) bool, True where it goes."""
    K, C = X.shape[:2]
    finite = np.isfinite(X).all(-1)                                       # (K, C)
    with np.errstate(invalid='ignore'):
        reach = np.linalg.norm(X[:, :, None] - X[:, None], axis=-1) <= link   # NaN: False
    reach |= np.eye(C, dtype=bool) & finite[:, :, None]
    for _ in range(max(1, int(np.ceil(np.log2(max(C, 2)))))):        # paths up to C joints
        reach = np.matmul(reach.astype(np.int64), reach.astype(np.int64)) > 0
    size = reach.sum(-1)                                  # (K, C): joints in its group
    return finite & (size < size.max(-1, initial=0, keepdims=True))


def foreign_views(instance, known, present, min_views):
    """The views of each subject to leave out as another hypothesis' crop's (module
    docstring, step 4).

    instance (S, V) int: each subject's crop slot (hypothesis) per view, -1 = none; known
    (H,) bool: the hypotheses with a predicted body (at least one joint known: a track or
    a discovered subject; not a live crop of unknown joints); present (S, V, C) bool: the
    subjects' detections; min_views: the fewest views a keypoint keeps. A subject's own
    hypothesis is the one whose crops give most of its instances (none on a tie: nothing
    is foreign). -> (S, V, C) bool: True where the view's instance came from another
    hypothesis with a predicted body, for each keypoint of which at least min_views of
    the subject's other detections remain."""
    instance = np.asarray(instance, np.int64)
    known = np.asarray(known, bool)
    S, V = instance.shape
    H = len(known)
    drop = np.zeros(present.shape, bool)
    if not S or not H:
        return drop
    count = (instance[:, :, None] == np.arange(H)).sum(1)                 # (S, H)
    home = np.argmax(count, axis=1)
    top = count[np.arange(S), home]
    alone = (top > 0) & ((count == top[:, None]).sum(1) == 1)            # (S,)
    other = ((instance >= 0) & (instance != home[:, None]) & alone[:, None]
             & known[np.maximum(instance, 0)])                             # (S, V)
    drop = other[..., None] & present                                      # (S, V, C)
    left = (present & ~drop).sum(1)                                         # (S, C)
    return drop & (left >= min_views)[:, None]


def home_hypotheses(instance, H):
    """Each subject's own hypothesis (module docstring step 4): the one whose crops give most
    of its instances. instance (S, V) int crop slots (-1: none), H hypotheses. -> (S,) int,
    -1 where none or a tie."""
    instance = np.asarray(instance, np.int64)
    S = len(instance)
    if not S or not H:
        return np.full(S, -1, np.int64)
    count = (instance[:, :, None] == np.arange(H)).sum(1)                 # (S, H)
    home = np.argmax(count, axis=1)
    top = count[np.arange(S), home]
    alone = (top > 0) & ((count == top[:, None]).sum(1) == 1)
    return np.where(alone, home, -1)


def unsettled_joints(view_errors, inliers, ratio, floor_px, min_views=2):
    """The joints to solve again (module docstring step 4b): view_errors / inliers (S, V, C)
    of an Association. A joint's error is the mean reprojection error (px) of its inlier
    views; it is flagged where that exceeds the subject's tolerance, the larger of floor_px
    and ratio x the median of the subject's joints' errors, or where it has only min_views
    inlier views (nothing to check the pair against) and the median of the subject's
    triangulated joints more than twice as many. -> (flag (S, C) bool, tolerance (S,)
    px)."""
    n = inliers.sum(1)                                                     # (S, C)
    with np.errstate(invalid='ignore', divide='ignore'):
        err = np.where(inliers, view_errors, 0.0).sum(1) / n
    err[n == 0] = np.nan
    median = np.zeros(len(err))
    some = np.isfinite(err).any(-1)
    if some.any():
        median[some] = np.nanmedian(err[some], axis=-1)
    tol = np.maximum(floor_px, ratio * median)
    with np.errstate(invalid='ignore'):
        flag = err > tol[:, None]                                          # NaN: False
    views = np.zeros(len(err))
    if some.any():
        views[some] = np.nanmedian(np.where(n[some] > 0, n[some], np.nan), axis=-1)
    return flag | ((n == min_views) & (2 * n < views[:, None])), tol


def settle_joints(a, cameras, cand_pts, cand_conf, subjects, ratio, floor_px, config):
    """Step 4b of the module docstring, in place on the Association a (with points2d /
    scores2d): the flagged joints (unsettled_joints) of the subjects `subjects` (S,) bool
    are solved again by geometry.select_candidates from the candidate peaks of the
    subject's crops, the peaks another subject took for that keypoint in that view
    (points2d within half config.threshold_px) left out, and triangulated as associate
    does (config: AssociationConfig); the new joint replaces the old one where it has at
    least min_views inlier views and a smaller mean reprojection error, or more inlier
    views with the error within the subject's tolerance (X, inliers, view_errors, score,
    points2d, scores2d). cameras: the V Cameras; cand_pts (V, H, C, k, 2)
    source px / cand_conf (V, H, C, k): the peaks of the crop of each view and hypothesis
    (crop slot; NaN / 0: none). -> int: joints replaced."""
    from monet_ros.geometry import select_candidates
    from monet_ros.subjects.association import triangulate_scored

    S, V, C = a.inliers.shape
    flag, tol = unsettled_joints(a.view_errors, a.inliers, ratio, floor_px, config.min_views)
    flag &= np.asarray(subjects, bool)[:, None]
    s_all, c_all = np.nonzero(flag)
    if not len(s_all):
        return 0
    n = len(s_all)
    slot = a.instance[s_all]                                               # (n, V)
    seen = slot >= 0
    rows = np.arange(V)[None]
    pts = cand_pts[rows, np.maximum(slot, 0), c_all[:, None]]              # (n, V, k, 2)
    w = np.where(seen[..., None], cand_conf[rows, np.maximum(slot, 0), c_all[:, None]], 0.0)
    # a peak another subject took for this keypoint in this view is that subject's
    others = a.points2d[:, :, c_all].transpose(2, 0, 1, 3).copy()         # (n, S, V, 2)
    others[np.arange(n), s_all] = np.nan
    with np.errstate(invalid='ignore'):
        d = np.linalg.norm(pts[:, None] - others[..., None, :], axis=-1)    # (n, S, V, k)
    w = np.where((d <= config.threshold_px / 2).any(1), 0.0, w)
    pts = np.where((w > 0)[..., None], pts, np.nan)
    new_pts = np.full((n, V, 2), np.nan)
    new_w = np.zeros((n, V))
    for s in np.unique(s_all).tolist():         # a few subjects: one tolerance each
        j = np.flatnonzero(s_all == s)
        choice, support = select_candidates(pts[j].transpose(1, 0, 2, 3), cameras,
                                            w[j].transpose(1, 0, 2), threshold_px=tol[s])
        pick = np.take_along_axis(pts[j], choice.T[..., None, None], axis=2)[:, :, 0]
        pick_w = np.take_along_axis(w[j], choice.T[..., None], axis=2)[..., 0]
        ok = support.T & (pick_w > 0)
        new_pts[j] = np.where(ok[..., None], pick, np.nan)
        new_w[j] = np.where(ok, pick_w, 0.0)
    X, inl, err, score = triangulate_scored(new_pts.transpose(1, 0, 2), new_w.T, cameras, config)
    old_inl = a.inliers[s_all, :, c_all]                                   # (n, V)
    with np.errstate(invalid='ignore', divide='ignore'):
        new = np.where(inl, err, 0.0).sum(0) / inl.sum(0)
        old = np.where(old_inl, a.view_errors[s_all, :, c_all], 0.0).sum(-1) / old_inl.sum(-1)
    more = (inl.sum(0) > old_inl.sum(-1)) & (new <= tol[s_all])
    better = (inl.sum(0) >= config.min_views) & np.isfinite(X).all(-1) & ((new < old) | more)
    s, c, i = s_all[better], c_all[better], np.flatnonzero(better)
    a.X[s, c] = X[i]
    a.inliers[s, :, c] = inl[:, i].T
    a.view_errors[s, :, c] = err[:, i].T
    a.score[s, c] = score[i]
    a.points2d[s, :, c] = new_pts[i]
    a.scores2d[s, :, c] = new_w[i]
    return int(better.sum())


def heat_matrices(heat_cameras):
    """(N, 3, 3) K_heat of heatmap Cameras or of (3, 3) matrices."""
    return np.stack([np.asarray(getattr(c, 'K', c), np.float64) for c in heat_cameras])


def map_centres(cameras, views, K_heat, sizes):
    """Where heatmaps lie in their source images: cameras, the source Cameras; views (N,)
    int the view of each map, K_heat (N, 3, 3) (or heatmap Cameras), sizes (N,) (h, w) of
    the maps. -> centre (N, 2) source px (pixel centres) of each map's centre, half (N, 2)
    source px: its half width and half height."""
    views = np.asarray(views, np.int64)
    N = len(views)
    rig = stack_cameras([cameras[v] for v in views])
    S, _ = crop_scales(heat_matrices(K_heat), rig['K'], rig['K_inv'])
    hw = np.asarray(sizes, np.float64).reshape(N, 2)
    centre = heat_to_source_points(((hw[:, ::-1] - 1) / 2)[:, None], S)[:, 0]     # (N, 2)
    half = hw[:, ::-1] / 2 / np.diagonal(S, axis1=1, axis2=2)[:, :2]              # (N, 2)
    return centre, half


def crop_instances(heat, heat_cameras, cameras, targets, config, confidence_threshold,
                   rivals=None, candidates=False):
    """One instance per crop (module docstring, step 3).

    heat: N heatmaps (C, h, w); heat_cameras / cameras: their heatmap (or (3, 3) K_heat)
    and source Cameras;
    targets (N, C, 2) source px of the hypothesis' joints in each crop's view (NaN:
    unknown); rivals (N, R, C, 2) or None: the other hypotheses' joints in that view (NaN:
    none): a chosen peak nearer a rival's joint than its target is left out
    (config.rival_peaks). -> points (N, C, 2) source px (NaN: no peak), score (N, C); with
    candidates, also every usable peak: (N, C, k, 2) source px (NaN: none) and (N, C, k)
    values (0 there), k = config.crop_peaks."""
    from monet_ros.models import decode_heatmap_peaks

    rig = stack_cameras(cameras)
    S, _ = crop_scales(heat_matrices(heat_cameras), rig['K'], rig['K_inv'])
    k = config.crop_peaks
    peaks, conf, _ = decode_heatmap_peaks(list(heat), k, floor=confidence_threshold)
    pts = heat_to_source_points(peaks, S)                          # (N, C, k, 2)
    usable = (conf >= confidence_threshold) & np.isfinite(pts).all(-1)
    dist = np.linalg.norm(pts - targets[:, :, None], axis=-1)
    # the nearest usable peak; the highest (index 0) where the target is unknown
    dist = np.where(np.isfinite(targets).all(-1)[..., None], dist, np.arange(k))
    pick = np.argmin(np.where(usable, dist, np.inf), axis=-1)      # (N, C)
    chosen = np.take_along_axis(pts, pick[..., None, None], axis=2)[:, :, 0]
    score = np.take_along_axis(conf, pick[..., None], axis=2)[..., 0]
    found = np.take_along_axis(usable, pick[..., None], axis=2)[..., 0]
    if rivals is not None and rivals.shape[1]:
        own = np.linalg.norm(chosen - targets, axis=-1)                       # (N, C)
        rival = np.linalg.norm(chosen[:, None] - rivals, axis=-1)             # (N, R, C)
        with np.errstate(invalid='ignore'):
            found &= ~(rival < own[:, None]).any(1)                # NaN compares False
    out = np.where(found[..., None], chosen, np.nan), np.where(found, score, 0.0)
    if candidates:
        return out + (np.where(usable[..., None], pts, np.nan), np.where(usable, conf, 0.0))
    return out


class SubjectsCore:
    """The detector-free part of the module docstring's algorithm, shared by `monet process
    --subjects` (SubjectsStep, which runs the detector) and the live fusion node with
    `subjects` >= 2 (its crops come from the detector nodes): the hypotheses (step 1's
    tracks), discovery from full-frame heatmaps (steps 1a-e) and, from the crops' heatmaps,
    steps 3-6 (resolve). No ROS, no network.

    num_keypoints: C; units: the rig's length unit; config: SubjectsConfig; association:
    AssociationConfig (its confidence_threshold is the peaks' too); tracker:
    subjects.TrackerConfig; rule: crop_rule.TrackedRule. Counters: tracker.births /
    deaths."""

    def __init__(self, num_keypoints, units, config=None, association=None, tracker=None,
                 rule=None):
        self.config = config or SubjectsConfig()
        self.association = association or AssociationConfig()
        self.rule = rule or TrackedRule()
        self.C = int(num_keypoints)
        self.units = units
        self.tracker = SubjectTracker(self.C, tracker, units=units,
                                      max_tracks=self.config.subjects)
        self._gate = from_mm(self.tracker.config.gate_mm, units)
        self._link = from_mm(self.config.link_mm, units)
        self._duplicate = from_mm(self.config.duplicate_mm, units)
        self._missed = np.zeros(0, np.int64)      # per tracker track: frames since matched
        self._frame = 0                           # frames resolved so far
        self._born = {}                           # identity -> the frame it was born in
        self._cropped = np.zeros(0, np.int64)     # identities of this frame's track hypotheses
        self._point_association = AssociationConfig(**{
            **{f: getattr(self.association, f) for f in (
                'threshold_px', 'confidence_threshold', 'min_views', 'triangulation_px',
                'method')}, 'min_common': 1, 'strong_common': 1})

    def hypotheses(self, stamp_ns):
        """Step 1: the predicted joints (cropped, C, 3) at stamp_ns of the tracks that get
        crops (cropped_tracks; NaN: joints not started)."""
        cropped = self.cropped_tracks()
        self._cropped = self.tracker.ids[cropped]
        return self.tracker.predicted(stamp_ns)[cropped]

    def discover_heatmaps(self, heat, heat_cameras, cameras, predicted, views=None):
        """(hypotheses (H, C, 3), counts dict: points, explained, loose, repeated) of
        full-frame heatmaps (module docstring step 1a-e), none near the predicted joints
        (tracks, C, 3) of the cropped tracks. heat: M maps (C, h, w); heat_cameras: their
        heatmap Cameras (or (3, 3) K_heat arrays); cameras: the V source Cameras; views (M,)
        int: the view of each map (None: one map per view, in order); a view's maps (its
        tiles) are merged by merge_peaks."""
        from monet_ros.models import decode_heatmap_peaks

        V = len(cameras)
        views = np.arange(V) if views is None else np.asarray(views, np.int64)
        rig = stack_cameras([cameras[v] for v in views])
        S, _ = crop_scales(heat_matrices(heat_cameras), rig['K'], rig['K_inv'])
        thr = self.association.confidence_threshold
        k = self.config.candidates
        peaks, conf, _ = decode_heatmap_peaks(list(heat), k, floor=thr)
        pts = heat_to_source_points(peaks, S)                       # (M, C, k, 2)
        if len(views) != V or (views != np.arange(V)).any():
            pts, conf = merge_peaks(pts, conf, views, V, k, self.association.threshold_px / 2)
        return self.discover_peaks(pts, conf, cameras, predicted)

    def discover_peaks(self, pts, conf, cameras, predicted):
        """Steps 1b-e of the peaks pts (V, C, k, 2) source px (NaN: none), conf (V, C, k)
        of the V views `cameras`; as discover_heatmaps."""
        points, keypoint, views = [], [], []
        counts = dict(points=0, explained=0, loose=0, repeated=0)
        for c in range(self.C):
            a = associate(pts[:, c, :, None], cameras, conf[:, c, :, None],
                          self._point_association)
            X = a.X[:, 0]
            ok = np.isfinite(X).all(-1)
            counts['points'] += int(ok.sum())
            if len(predicted):
                near = np.linalg.norm(X[:, None] - predicted[None, :, c], axis=-1)
                explained = ok & (near <= self._gate).any(-1)
                counts['explained'] += int(explained.sum())
                ok &= ~explained
            points.append(X[ok])
            keypoint.append(np.full(int(ok.sum()), c))
            views.append((a.instance[ok] >= 0).sum(-1))
        points, keypoint, views = (np.concatenate(x) for x in (points, keypoint, views))
        need = self.config.subjects - len(predicted)
        found = []
        for group in group_points(points, keypoint, views, self._link):
            if len(group) < self.tracker.config.min_keypoints or len(found) == need:
                counts['loose'] += len(group)
                continue
            X = np.full((self.C, 3), np.nan)
            X[keypoint[group]] = points[group]
            if repeated_body(X, found, self._gate):
                counts['repeated'] += len(group)
                continue
            found.append(X)
        return np.array(found).reshape(-1, self.C, 3), counts

    def crop_boxes(self, cameras, hyp):
        """Step 2: (V, H, 4) boxes (x0, y0, x1, y1, source px edges; NaN: too few joints
        project into the view) of the hypotheses hyp (H, C, 3) in every view."""
        boxes = np.full((len(cameras), len(hyp), 4), np.nan)
        for h in range(len(hyp)):
            boxes[:, h] = subject_boxes(cameras, hyp[h], self.rule.margin,
                                        self.rule.min_points, trim=self.rule.trim)
        return boxes

    def resolve(self, cameras, stamp_ns, hyp, v_idx, h_idx, heat, heat_cameras, tracked=0,
                discovered=-1, counts=None):
        """Steps 3-6 of the module docstring: one instance per crop, association across
        views, duplicates and shared joints, the tracker. -> FrameSubjects.

        cameras: the V source Cameras of the frame; stamp_ns: its stamp (increasing);
        hyp (H, C, 3): the hypotheses (rig units; NaN joints: unknown, the crop takes its
        highest peaks); crop n is of view v_idx[n] and hypothesis h_idx[n] (at most one crop
        per view and hypothesis), heat[n] its map (C, h, w), heat_cameras[n] its heatmap
        Camera (or (3, 3) K_heat); tracked: how many hypotheses are tracks, discovered: how
        many were discovered (-1: no discovery), counts: discovery's counts."""
        V, H = len(cameras), len(hyp)
        v_idx, h_idx = np.asarray(v_idx, np.int64), np.asarray(h_idx, np.int64)
        points = np.full((V, H, self.C, 2), np.nan)
        score = np.zeros((V, H, self.C))
        k = self.config.crop_peaks
        cand_pts = np.full((V, H, self.C, k, 2), np.nan)                # step 4b's candidates
        cand_conf = np.zeros((V, H, self.C, k))
        if len(v_idx):
            crop_cams = [cameras[v] for v in v_idx]
            known = np.isfinite(hyp).all(-1)                          # (H, C)
            projected = project_views(stack_cameras(cameras),
                                      np.where(known[..., None], hyp, 0.0).reshape(-1, 3))
            projected = projected.reshape(V, H, self.C, 2)
            projected[:, ~known] = np.nan
            targets = projected[v_idx, h_idx]
            rivals = None
            if self.config.rival_peaks:      # (crops, H - 1, C, 2): the other hypotheses
                others = np.arange(H)[None] != h_idx[:, None]                 # (N, H)
                rivals = projected[v_idx][others].reshape(len(v_idx), H - 1, self.C, 2)
            p, s, cp, cc = crop_instances(heat, heat_cameras, crop_cams, targets, self.config,
                                          self.association.confidence_threshold, rivals,
                                          candidates=True)
            points[v_idx, h_idx], score[v_idx, h_idx] = p, s
            cand_pts[v_idx, h_idx], cand_conf[v_idx, h_idx] = cp, cc
        if V:
            a = associate(points, cameras, score, self.association)
        else:                     # no view at all (live: every slot of the instant empty)
            a = Association(X=np.zeros((0, self.C, 3)), instance=np.zeros((0, 0), np.int64),
                            inliers=np.zeros((0, 0, self.C), bool),
                            view_errors=np.zeros((0, 0, self.C)), score=np.zeros((0, self.C)),
                            cost=np.zeros(0), unmatched=0, instances=0,
                            points2d=np.zeros((0, 0, self.C, 2)),
                            scores2d=np.zeros((0, 0, self.C)))
        foreign = 0
        if self.config.foreign_views and len(a.X):
            drop = foreign_views(a.instance, np.isfinite(hyp).all(-1).any(-1),
                                 a.scores2d > 0, self.association.min_views)
            foreign = leave_out_views(a, cameras, drop, self.association)
        settled = 0
        if self.config.settle_frames and len(a.X):
            settled = settle_joints(a, cameras, cand_pts, cand_conf,
                                    self.young(a.instance, H, tracked), self.config.settle_ratio,
                                    self.config.settle_px, self.association)
        keep = []
        weak = weak_subjects(a.score, self.config.min_score)
        for s in np.flatnonzero(~weak).tolist():
            d = np.linalg.norm(a.X[s] - a.X[keep], axis=-1)               # (kept, C)
            both = np.isfinite(d)
            with np.errstate(invalid='ignore', divide='ignore'):
                mean = np.where(both, d, 0.0).sum(-1) / both.sum(-1)
            if not (mean < self._duplicate).any():
                keep.append(s)
        duplicates = len(a.X) - int(weak.sum()) - len(keep)
        extra = max(0, len(keep) - self.config.subjects)
        keep = claimed_first(a.instance, np.array(keep, np.int64), H)
        keep = keep[:self.config.subjects]
        shared = shared_joints(a.X[keep], self._duplicate)
        X = np.where(shared[..., None], np.nan, a.X[keep])
        detached = detached_joints(X, self._link)
        drop = shared | detached
        if drop.any():
            s, c = np.nonzero(drop)
            a.X[keep[s], c] = np.nan
            a.inliers[keep[s], :, c] = False
            a.view_errors[keep[s], :, c] = np.nan
            a.score[keep[s], c] = np.nan
            a.points2d[keep[s], :, c] = np.nan           # the neighbour's: not this subject's
            a.scores2d[keep[s], :, c] = 0.0
        tracker = self.tracker
        before = dict(zip(tracker.ids.tolist(), self._missed.tolist()))
        ids = tracker.step(a.X[keep], stamp_ns)
        for i in ids[ids >= 0].tolist():
            self._born.setdefault(i, self._frame)
        self._frame += 1
        self.count_misses(before, ids)
        self.restart(ids, drop)
        return FrameSubjects(association=a, keep=keep, ids=ids, hypotheses=H,
                             discovered=discovered, crops=len(v_idx), duplicates=duplicates,
                             extra=extra, tracked=tracked, shared=int(shared.sum()),
                             detached=int(detached.sum()), weak=int(weak.sum()),
                             foreign=foreign, settled=settled,
                             **(counts or {}))

    def young(self, instance, H, tracked):
        """Which subjects settle (module docstring step 4b): instance (S, V) their crop slots
        (hypotheses, the first `tracked` of them this frame's tracks, in hypotheses()'
        order), H hypotheses. -> (S,) bool: True where the subject's own hypothesis
        (home_hypotheses) is not a track (discovered this frame, or a live crop of unknown
        joints) or is a track born at most settle_frames frames ago."""
        home = home_hypotheses(instance, H)
        young = np.ones(H, bool)
        born = np.array([self._born.get(i, self._frame) for i in self._cropped[:tracked]
                         .tolist()], np.int64)
        young[:len(born)] = self._frame - born <= self.config.settle_frames
        return (home >= 0) & young[np.maximum(home, 0)]

    def live_frame(self, cameras, stamp_ns, crops, full=()):
        """One frame of the live fusion node (`subjects` >= 2): the crops were cut by the
        detector nodes, around the subjects of the latest /monet/keypoints3d, plus the
        discovery maps of each view (its whole frame, or its tiles: discovery_boxes) while
        fewer than N subjects were published. The same steps as SubjectsStep.step, the
        crops given instead of made:

        - hypotheses: the cropped tracks' predictions (step 1); with discovery maps and
          fewer than N of them, discovery on those maps (discover_heatmaps, steps 1a-e: a
          view's tiles merged by merge_peaks, as offline); each discovered hypothesis, and
          each track without a crop of its own in a view, takes one of that view's
          discovery maps as its crop there (the detector has no crop of it): the whole
          frame, or of its tiles the one that holds its projected joints with the most
          room (fallback_maps);
        - each subject crop is the crop of the track given by match_crops (per view, the
          Hungarian assignment of crop centres to the tracks' crop-rule box centres); a crop
          matched to none is a hypothesis of unknown joints (its highest peaks, step 3);
        - resolve (steps 3-6).

        cameras: the V source Cameras of the views present; crops / full: (view index,
        heat (C, h, w), K_heat (3, 3)) of the subject crops / discovery maps (a view's
        tiles in discovery_boxes' order, the views in increasing order).
        -> FrameSubjects."""
        predicted = self.hypotheses(stamp_ns)
        new, counts, discovered = np.zeros((0, self.C, 3)), {}, -1
        full_views = np.array([f[0] for f in full], np.int64)
        if len(full) and len(predicted) < self.config.subjects:
            seen = np.unique(full_views)                      # views with discovery maps
            new, counts = self.discover_heatmaps(
                [f[1] for f in full], [f[2] for f in full], [cameras[v] for v in seen],
                predicted, np.searchsorted(seen, full_views))
            discovered = len(new)
        owner = self.match_crops(cameras, predicted, [c[0] for c in crops],
                                 [c[2] for c in crops], [c[1].shape[1:] for c in crops])
        unknown = int((owner < 0).sum())
        owner[owner < 0] = len(predicted) + len(new) + np.arange(unknown)
        hyp = np.concatenate([predicted, new, np.full((unknown, self.C, 3), np.nan)])
        v_idx, h_idx = [c[0] for c in crops], owner.tolist()
        heat, K = [c[1] for c in crops], [c[2] for c in crops]
        # a track without a crop of its own in a view, and every discovered subject, takes
        # one of that view's discovery maps as its crop
        owned = set(zip(v_idx, h_idx))
        fallback = self.fallback_maps(cameras, hyp[:len(predicted) + len(new)], full)
        for (v, h), n in fallback.items():
            if (v, h) not in owned:
                v_idx.append(v)
                h_idx.append(h)
                heat.append(full[n][1])
                K.append(full[n][2])
        return self.resolve(cameras, stamp_ns, hyp, v_idx, h_idx, heat, K,
                            tracked=len(predicted), discovered=discovered, counts=counts)

    def fallback_maps(self, cameras, hyp, full):
        """Which discovery map each hypothesis takes as its crop in a view (live_frame): hyp
        (H, C, 3), full: (view index, heat (C, h, w), K_heat) maps. -> {(view, hypothesis):
        index into full}: a view's only map for every hypothesis; of several (tiles), the
        one that holds its known joints projected into the view (in front of it and
        within an image size of its borders) with the most room: the largest distance
        (source px) of the joint nearest a tile edge (negative outside), so the tile
        that holds the whole body when one does (tiles overlap by half: a body up to half
        a tile's side fits in one); none where no joint projects (no crop there)."""
        out = {}
        if not len(full) or not len(hyp):
            return out
        views = np.array([f[0] for f in full], np.int64)
        several = np.bincount(views)[views] > 1
        if several.any():
            centre, half = map_centres(cameras, views, [f[2] for f in full],
                                       [f[1].shape[1:] for f in full])
            rig = stack_cameras(cameras)
            known = np.isfinite(hyp).all(-1)                                  # (H, C)
            uv = project_views(rig, np.where(known[..., None], hyp, 0.0).reshape(-1, 3))
            uv = uv.reshape(len(cameras), *known.shape, 2)                    # (V, H, C, 2)
            depth = (np.einsum('vij,hcj->vhci', rig['R'], np.nan_to_num(hyp))
                     + rig['t'][:, None, None])[..., 2]
            size = np.array([[c.width, c.height] for c in cameras], np.float64)[:, None, None]
            inside = (known[None] & (depth > 0) & np.isfinite(uv).all(-1)
                      & (uv > -size).all(-1) & (uv < 2 * size).all(-1))          # (V, H, C)
        for v in np.unique(views).tolist():
            mine = np.flatnonzero(views == v)
            for h in range(len(hyp)):
                if len(mine) == 1:
                    out[v, h] = int(mine[0])
                elif inside[v, h].any():
                    joints = uv[v, h, inside[v, h]]                                # (n, 2)
                    room = (half[mine, None] - np.abs(joints[None] - centre[mine, None]))
                    out[v, h] = int(mine[np.argmax(room.min(-1).min(-1))])
        return out

    def match_crops(self, cameras, hyp, views, K_heat, sizes):
        """Which hypothesis each live crop was cut for: per view, the assignment
        (scipy linear_sum_assignment) of the crops' centres to the centres of the
        hypotheses' crop-rule boxes (crop_boxes) minimising the total distance, a pair
        allowed where the box centre lies within the crop's half-size (max of its half
        width and height) of the crop's centre. cameras: V source Cameras; hyp (H, C, 3);
        views (N,) the crops' view indices, K_heat (N, 3, 3), sizes (N,) (h, w) of their
        maps. -> (N,) int: the hypothesis of each crop, -1 for none."""
        from scipy.optimize import linear_sum_assignment

        N = len(views)
        owner = np.full(N, -1, np.int64)
        if not N or not len(hyp):
            return owner
        views = np.asarray(views, np.int64)
        centre, half = map_centres(cameras, views, K_heat, sizes)
        half = half.max(-1)                                   # the larger half side (N,)
        boxes = self.crop_boxes(cameras, hyp)                         # (V, H, 4)
        box_centre = (boxes[..., :2] + boxes[..., 2:]) / 2 - 0.5      # pixel centres
        for v in np.unique(views):
            mine = np.flatnonzero(views == v)
            d = np.linalg.norm(centre[mine, None] - box_centre[v][None], axis=-1)
            allowed = np.isfinite(d) & (d <= half[mine, None])
            big = 1e6 * (np.nanmax(np.where(allowed, d, 0.0)) + 1.0)
            rows, cols = linear_sum_assignment(np.where(allowed, d, big))
            ok = allowed[rows, cols]
            owner[mine[rows[ok]]] = cols[ok]
        return owner

    def restart(self, ids, drop):
        """Unstart the tracker joints `drop` (K, C) bool of the subjects given the
        identities ids (K,) (module docstring step 5): predicted() is NaN there, so the
        next frame's crops take their highest peak for it (step 3)."""
        s, c = np.nonzero(drop)
        rows = np.searchsorted(self.tracker.ids, ids[s])      # ids increase in the tracker
        ok = (ids[s] >= 0) & (rows < len(self.tracker.ids))
        ok[ok] &= self.tracker.ids[rows[ok]] == ids[s][ok]
        self.tracker.started[rows[ok], c[ok]] = False

    def count_misses(self, before, ids):
        """Frames since each tracker track was last matched, after a tracker step that gave
        the identities `ids` (matched or born: 0); before: {identity: count} of the tracks
        before that step."""
        matched = set(np.asarray(ids).tolist())
        self._missed = np.array([0 if i in matched else before.get(i, -1) + 1
                                 for i in self.tracker.ids.tolist()], np.int64)

    def cropped_tracks(self):
        """Indices (into the tracker's tracks) of the tracks that get crops this frame
        (module docstring step 1): matched within the last crop_missed frames, at most N,
        the most recently matched first, then the oldest identity."""
        ok = np.flatnonzero(self._missed < self.config.crop_missed)
        order = np.lexsort((self.tracker.ids[ok], self._missed[ok]))
        return ok[order][:self.config.subjects]


class SubjectsStep(SubjectsCore):
    """The several-subject step of the module docstring over a stream of frames, with the
    detector in the loop (`monet process --subjects`; SubjectsCore is the rest).

    detector: a models.Detector; its keypoints give C; the other arguments as
    SubjectsCore's. step(images, cameras, stamp_ns) -> FrameSubjects."""

    def __init__(self, detector, units, config=None, association=None, tracker=None,
                 rule=None):
        super().__init__(len(detector.keypoints), units, config, association, tracker, rule)
        self.detector = detector

    def discover(self, images, cameras, predicted, encodings=None):
        """discover_heatmaps of one full-frame detection of every view (module docstring
        step 1); encodings: as in step."""
        boxes = discovery_boxes(self.detector, cameras, self.config.discovery_tiles)
        views = np.repeat(np.arange(len(cameras)), [len(b) for b in boxes])
        heat, heat_cameras = self.detector.predict(
            [images[v] for v in views], [cameras[v] for v in views], np.concatenate(boxes),
            keep_aspect=False,
            encodings=None if encodings is None else [encodings[v] for v in views])
        return self.discover_heatmaps(heat, heat_cameras, cameras, predicted, views)

    def step(self, images, cameras, stamp_ns, encodings=None):
        """images: (H, W, 3) uint8 RGB of the present views, or each in its own layout
        (encodings: one per image, as models.Detector.predict takes them: converted to RGB
        only after cropping); cameras: their Cameras (at least 2); stamp_ns: the frame's
        stamp. -> FrameSubjects."""
        predicted = self.hypotheses(stamp_ns)                         # (cropped, C, 3)
        discovered = -1
        hyp = predicted
        counts = {}
        if len(predicted) < self.config.subjects:
            new, counts = self.discover(images, cameras, predicted, encodings)
            discovered = len(new)
            hyp = np.concatenate([predicted, new])
        boxes = self.crop_boxes(cameras, hyp)
        v_idx, h_idx = np.nonzero(np.isfinite(boxes).all(-1))        # (V, H)
        heat, heat_cameras = [], []
        if len(v_idx):
            heat, heat_cameras = self.detector.predict(
                [images[v] for v in v_idx], [cameras[v] for v in v_idx], boxes[v_idx, h_idx],
                encodings=None if encodings is None else [encodings[v] for v in v_idx])
        return self.resolve(cameras, stamp_ns, hyp, v_idx, h_idx, heat, heat_cameras,
                            tracked=len(predicted), discovered=discovered, counts=counts)
