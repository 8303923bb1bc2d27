"""Synthesise a recording: rig + moving subject -> rosbag2 MCAP, rig file, labels, ground
truth and a README (the `monet synth` command; no rclpy: monet_ros.io writes CDR itself).

Output folder DIR (must not exist or be empty):
  DIR/recording/        rosbag2 MCAP: /camK/image_raw (Image rgb8), /camK/camera_info,
                        /tf_static (world -> camK_optical), /ground_truth/keypoints3d
                        (PointCloud2, one point per keypoint; num_views = views in which it
                        projects inside the image)
  DIR/rig.yaml          geometry.save_rig (frame 'world')
  DIR/labels.csv        monet_ros.labels format for the labelled instants
  DIR/ground_truth.npz  stamps (T,), keypoints3d (T, C, 3), keypoints2d (T, V, C, 2),
                        in_image / occluded (T, V, C), labelled (T,) bool, camera_names,
                        keypoint_names
  DIR/README.md         what, seed, cameras, frames, labels, how to train / evaluate
With --subjects N > 1 (SynthConfig.subjects) the images show N subjects; the ground-truth
topic and labels.csv are subject 0's (--label-subjects: labels.csv labels every subject,
with a subject column); ground_truth.npz adds subjects_keypoints3d
(T, S, C, 3), subjects_keypoints2d (T, V, S, C, 2), subjects_in_image and
subjects_occluded (T, V, S, C) (hidden by any subject's limbs), subject s in slot s (its
identity); DIR/points2d.csv holds every subject's visible keypoints per camera as the
frames table with a `subject` column whose instance labels are shuffled per camera and
frame (`monet triangulate DIR/points2d.csv --subjects N`).
"""
from dataclasses import asdict, dataclass, field
from pathlib import Path
import sys
import time

import numpy as np

from monet_ros.geometry import save_rig
from monet_ros.labels import label_rows, write_labels
from monet_ros.skeleton import SkeletonError, load_skeleton
from monet_ros.synth.render import (
    RenderConfig,
    Scene,
    capsule_outlines,
    in_image,
    occlusion,
    sided_parts,
)
from monet_ros.synth.rig import LAYOUTS, RigConfig, RigConfigError, make_rig
from monet_ros.synth.subject import Subject, SubjectError
from monet_ros.synth.subjects import PATH_RADII, make_subjects

DEFAULT_START_NS = 1_767_225_600_000_000_000          # 2026-01-01T00:00:00Z
GROUND_TRUTH_TOPIC = '/ground_truth/keypoints3d'
FRAME_ID = 'world'

# SynthConfig field -> RigConfig field (to name the user's field in errors)
_RIG_FIELDS = {'cameras': 'num_cameras', 'layout': 'layout', 'width': 'image_width',
               'height': 'image_height', 'distortion': 'distortion', 'radius': 'radius',
               'hfov_deg': 'hfov_deg', 'jitter': 'jitter', 'height_spread': 'height_spread'}


class SynthError(ValueError):
    """Bad synth configuration or output path; the message names the field or path."""


@dataclass(frozen=True)
class SynthConfig:
    """A synthetic recording (all fields validated on construction; errors name the field).

    cameras: number of cameras; frames: instants; fps: frame rate; width, height: image
    size; skeleton: preset name (human14, quadruped13) or YAML path; layout: ring | dome;
    label_fraction: fraction of instants with 2D labels in every view (at least one
    instant is labelled); seed: everything random derives from it; distortion: OpenCV
    (k1[, k2, p1, p2, k3]); radius: camera distance (m; None = 4.0 for a human, 2.5 for a
    quadruped); hfov_deg: horizontal field of view; jitter: rig perturbation scale;
    motion_seed: the subjects' motion (paths, speeds, gestures) only, so two recordings can
    share the rig, the look and the room (seed) and differ in motion (None = seed; a
    recording with motion_seed == seed has the message data of one without it);
    label_occluded: label keypoints hidden by other limbs too (True) or only visible ones;
    noise: sensor noise std (DN); start_ns: stamp of the first instant.
    height_spread: ring cameras alternately up to this many metres above / below the nominal
    height (non-coplanar ring; 0 = coplanar); occluders: static pillars (up to hip height)
    between the subject's path and that many cameras, hiding legs from some views;
    distinct_sides: the subject's left limbs in their own colour (left and right limbs look
    alike otherwise, the symmetric ambiguity of real subjects); subjects: 1, or 2..3
    subjects walking rings of synth.subjects.PATH_RADII that pass and hide each other
    (subject 0 is the one of the ground-truth topic and labels.csv; ground_truth.npz holds
    them all and points2d.csv their per-camera instances); label_subjects: labels.csv labels
    every subject at the labelled instants (its subject column: subject s is slot s of
    ground_truth.npz, the same id in every view), by the same rule as subject 0. All off by
    default: a seed's bytes do not change.
    """

    cameras: int = 8
    frames: int = 100
    fps: float = 30.0
    width: int = 640
    height: int = 480
    skeleton: str = 'human14'
    layout: str = 'ring'
    label_fraction: float = 0.005
    seed: int = 0
    distortion: tuple = (-0.08, 0.02)
    radius: float | None = None
    hfov_deg: float = 60.0
    jitter: float = 1.0
    label_occluded: bool = True
    noise: float = 3.0
    start_ns: int = DEFAULT_START_NS
    height_spread: float = 0.0
    occluders: int = 0
    distinct_sides: bool = False
    subjects: int = 1
    motion_seed: int | None = None
    label_subjects: bool = False
    rig: RigConfig = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        def bad(name, message):
            raise SynthError(f'synth config: field {name!r}: {message}')

        for name in ('cameras', 'frames', 'width', 'height', 'seed', 'start_ns'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                bad(name, f'must be an integer, got {value!r}')
        if not 1 <= self.frames <= 1_000_000:
            bad('frames', f'must be in 1..1000000, got {self.frames}')
        if not (np.isfinite(self.fps) and 0 < self.fps <= 1000):
            bad('fps', f'must be in (0, 1000], got {self.fps!r}')
        if not (np.isfinite(self.label_fraction) and 0 <= self.label_fraction <= 1):
            bad('label_fraction', f'must be in [0, 1], got {self.label_fraction!r}')
        if self.seed < 0:
            bad('seed', f'must be >= 0, got {self.seed}')
        if self.motion_seed is not None and (
                isinstance(self.motion_seed, bool)
                or not isinstance(self.motion_seed, (int, np.integer)) or self.motion_seed < 0):
            bad('motion_seed', f'must be an integer >= 0 or None, got {self.motion_seed!r}')
        if self.start_ns < 0:
            bad('start_ns', f'must be >= 0, got {self.start_ns}')
        if self.layout not in LAYOUTS:
            bad('layout', f'must be one of {LAYOUTS}, got {self.layout!r}')
        if not (np.isfinite(self.noise) and 0 <= self.noise <= 50):
            bad('noise', f'must be in 0..50, got {self.noise!r}')
        for name in ('label_occluded', 'distinct_sides', 'label_subjects'):
            if not isinstance(getattr(self, name), bool):
                bad(name, f'must be a bool, got {getattr(self, name)!r}')
        if isinstance(self.occluders, bool) or not isinstance(self.occluders, (int, np.integer)) \
                or not 0 <= self.occluders <= self.cameras:
            bad('occluders', f'must be an integer in 0..cameras ({self.cameras}), got '
                f'{self.occluders!r}')
        if isinstance(self.subjects, bool) or not isinstance(self.subjects, (int, np.integer)) \
                or not 1 <= self.subjects <= len(PATH_RADII):
            bad('subjects', f'must be an integer in 1..{len(PATH_RADII)}, got {self.subjects!r}')
        try:
            skeleton = load_skeleton(self.skeleton)
            subject = Subject(skeleton)
        except (SkeletonError, SubjectError) as error:
            bad('skeleton', str(error))
        radius = self.radius
        if radius is None:
            radius = 4.0 if subject.body == 'human' else 2.5
        height = subject.nominal_height
        try:
            rig = RigConfig(num_cameras=self.cameras, layout=self.layout, radius=radius,
                            camera_height=0.9 * height, target=(0.0, 0.0, 0.5 * height),
                            image_width=self.width, image_height=self.height,
                            hfov_deg=self.hfov_deg, distortion=tuple(self.distortion),
                            jitter=self.jitter, height_spread=self.height_spread)
        except RigConfigError as error:
            message = str(error)
            for ours, theirs in _RIG_FIELDS.items():
                if f"'{theirs}'" in message:
                    bad(ours, message.split(': ', 2)[-1])
            raise SynthError(message) from None
        object.__setattr__(self, 'distortion', rig.distortion)
        object.__setattr__(self, 'rig', rig)

    @property
    def labelled_count(self):
        """Number of labelled instants: round(fraction * frames), at least 1."""
        return max(1, min(self.frames, int(round(self.label_fraction * self.frames))))

    def stamps(self):
        """(T,) int64 stamps in ns: start_ns + round(k * 1e9 / fps)."""
        k = np.arange(self.frames, dtype=np.float64)
        return self.start_ns + np.round(k * 1e9 / self.fps).astype(np.int64)

    @property
    def subject_seed(self):
        """The seed of the subjects' motion: motion_seed, or seed when it is None."""
        return self.seed if self.motion_seed is None else int(self.motion_seed)

    def to_dict(self):
        data = asdict(self)
        data.pop('rig', None)
        if self.motion_seed is None:          # a seed's README stays as it was
            data.pop('motion_seed')
        if not self.label_subjects:
            data.pop('label_subjects')
        data['distortion'] = list(self.distortion)
        return data


@dataclass(frozen=True)
class SynthResult:
    out: Path
    frames: int
    cameras: int
    keypoints: int
    labelled_instants: int
    label_rows: int
    wall_s: float
    bag_bytes: int

    def summary(self):
        return (f'monet synth: wrote {self.frames} instants x {self.cameras} cameras '
                f'({self.keypoints} keypoints, {self.labelled_instants} labelled instants, '
                f'{self.label_rows} labels) to {self.out} in {self.wall_s:.1f} s '
                f'({self.bag_bytes / 1e6:.1f} MB bag)')


def labelled_indices(config):
    """Indices of the labelled instants: evenly spread with a seeded offset."""
    n = config.labelled_count
    offset = np.random.default_rng([config.seed, 0x4c41]).uniform()      # 'LA'
    idx = np.floor((np.arange(n) + offset) * config.frames / n).astype(int)
    return np.unique(np.clip(idx, 0, config.frames - 1))


OCCLUDER_RADIUS = 0.15                 # metres
OCCLUDER_HEIGHT = 0.55                 # fraction of the subject's height (legs, hands)


def occluder_capsules(cameras, count, X):
    """(count, 2, 3) end points of static pillars, each halfway between the centre of the
    subject's path and one of `count` cameras spread over the rig, up to hip height."""
    centre = np.nanmean(X.reshape(-1, 3), axis=0) * [1.0, 1.0, 0.0]
    top = OCCLUDER_HEIGHT * (np.nanmax(X[..., 2]) - np.nanmin(X[..., 2]))
    pick = np.floor(np.arange(count) * len(cameras) / count).astype(int)
    feet = [centre + 0.5 * (cameras[v].center * [1.0, 1.0, 0.0] - centre) for v in pick]
    return np.array([[f, f + [0.0, 0.0, top]] for f in feet])


def plan(config):
    """Everything but the images: cameras, skeleton, subject, stamps, ground truth.

    Returns a dict: cameras, skeleton, subject, stamps (T,), times (T,), keypoints3d
    (T, C, 3), A, B (T, P, 3) capsule axes (the subject's, then the occluders'), radii (P,),
    parts (P,) material names, keypoints2d (T, V, C, 2), in_image, occluded
    (T, V, C), labelled (T,) bool, label_mask (T, V, C) bool, root (T, 3) on the ground;
    all of subject 0 (occlusion by the other subjects included); and subjects_keypoints3d
    (T, S, C, 3), subjects_keypoints2d (T, V, S, C, 2), subjects_in_image and
    subjects_occluded (T, V, S, C) of every subject (A, B: every subject's capsules).
    """
    skeleton = load_skeleton(config.skeleton)
    subjects = [Subject(skeleton, seed=config.subject_seed)] if config.subjects == 1 else \
        make_subjects(skeleton, config.subjects, seed=config.subject_seed)
    subject = subjects[0]
    cameras = make_rig(config.rig, seed=config.seed)
    stamps = config.stamps()
    times = (stamps - stamps[0]) / 1e9
    every = [s.joints(times) for s in subjects]
    joints = every[0]
    S, C = len(subjects), skeleton.num_keypoints
    X_all = np.concatenate([np.stack([j[k] for k in skeleton.keypoints], axis=1)
                            for j in every], axis=1)                     # (T, S C, 3)
    X = X_all[:, :C]
    caps = [s.capsule_arrays(times, j) for s, j in zip(subjects, every)]
    A = np.concatenate([a for a, _ in caps], axis=1)
    B = np.concatenate([b for _, b in caps], axis=1)
    parts = (sided_parts(subject.capsules) if config.distinct_sides else subject.parts) * S
    radii = np.concatenate([s.radii for s in subjects])
    attached = np.zeros((len(radii), S * C), bool)                       # block diagonal
    for k, s in enumerate(subjects):
        P = len(s.radii)
        attached[k * P:(k + 1) * P, k * C:(k + 1) * C] = s.attached
    if config.occluders:
        ends = occluder_capsules(cameras, config.occluders, X)           # (K, 2, 3)
        A = np.concatenate([A, np.broadcast_to(ends[:, 0], (len(A), *ends[:, 0].shape))], 1)
        B = np.concatenate([B, np.broadcast_to(ends[:, 1], (len(B), *ends[:, 1].shape))], 1)
        radii = np.concatenate([radii, np.full(len(ends), OCCLUDER_RADIUS)])
        attached = np.concatenate([attached, np.zeros((len(ends), S * C), bool)])
        parts = parts + ('occluder',) * len(ends)
    uv_all, inside_all = in_image(cameras, X_all)
    hidden_all = occlusion(cameras, X_all, A, B, radii, attached)
    uv, inside, hidden = uv_all[:, :, :C], inside_all[:, :, :C], hidden_all[:, :, :C]
    labelled = np.zeros(config.frames, bool)
    labelled[labelled_indices(config)] = True
    mask = inside & labelled[:, None, None]
    if not config.label_occluded:
        mask &= ~hidden
    root = joints[subject.root_joint] * [1.0, 1.0, 0.0]             # shadow centre
    T, V = len(times), len(cameras)
    return dict(cameras=cameras, skeleton=skeleton, subject=subject, stamps=stamps,
                times=times, keypoints3d=X, A=A, B=B, radii=radii, parts=parts,
                keypoints2d=uv, in_image=inside,
                occluded=hidden, labelled=labelled, label_mask=mask, root=root,
                subjects_keypoints3d=X_all.reshape(T, S, C, 3),
                subjects_keypoints2d=uv_all.reshape(T, V, S, C, 2),
                subjects_in_image=inside_all.reshape(T, V, S, C),
                subjects_occluded=hidden_all.reshape(T, V, S, C))


def subject_label_rows(p, labelled, label_occluded=True):
    """(stamp_ns, camera, keypoint, u, v, subject) rows of every subject at the `labelled`
    instants (indices): the exact projections inside the image (and not hidden, unless
    label_occluded), subject s = slot s of subjects_keypoints2d; sorted by instant, camera,
    subject, keypoint."""
    uv = p['subjects_keypoints2d'][labelled]                       # (L, V, S, C, 2)
    ok = p['subjects_in_image'][labelled]
    if not label_occluded:
        ok = ok & ~p['subjects_occluded'][labelled]
    names = [c.name for c in p['cameras']]
    keypoints = p['skeleton'].keypoints
    stamps = p['stamps'][labelled]
    return [(int(stamps[t]), names[v], keypoints[c], float(uv[t, v, s, c, 0]),
             float(uv[t, v, s, c, 1]), int(s)) for t, v, s, c in zip(*np.nonzero(ok))]


def write_instances_table(path, p, seed):
    """The frames table (labels_import.points2d) with a `subject` column of every subject's
    visible keypoints (in the image, not hidden): exact projections, the instance labels
    i0, i1, ... in a random order per camera and frame (seeded), as a multi-animal
    detector's labels; -> rows written."""
    uv, ok = p['subjects_keypoints2d'], p['subjects_in_image'] & ~p['subjects_occluded']
    T, V, S, C = ok.shape
    names = [c.name for c in p['cameras']]
    label = np.argsort(np.random.default_rng([int(seed), 0x4953]).random((T, V, S)), -1)
    t, v, s, c = np.nonzero(ok)
    lines = ['frame,camera,keypoint,u,v,score,subject']
    keypoints = p['skeleton'].keypoints
    lines += [f'{a},{names[b]},{keypoints[d]},{float(uv[a, b, e, d, 0])!r},'
              f'{float(uv[a, b, e, d, 1])!r},1.0,i{label[a, b, e]}'
              for a, b, e, d in zip(t.tolist(), v.tolist(), s.tolist(), c.tolist())]
    Path(path).write_text('\n'.join(lines) + '\n')
    return len(lines) - 1


def _check_output(out):
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise SynthError(f'output {out} exists and is not an empty folder; not overwriting '
                         '(choose another --out)')
    out.mkdir(parents=True, exist_ok=True)
    return out


def write_frame(bag, cameras, stamp, images, X, num_views):
    """Write one instant: every camera's image + camera_info, then the ground truth."""
    for cam, image in zip(cameras, images):
        frame_id = f'{cam.name}_optical'
        bag.write_image(f'/{cam.name}/image_raw', stamp, image, frame_id, encoding='rgb8')
        bag.write_camera_info(f'/{cam.name}/camera_info', stamp, cam, frame_id)
    bag.write_keypoints3d(GROUND_TRUTH_TOPIC, stamp, FRAME_ID, X,
                          confidence=np.ones(len(X)), reprojection_error=np.zeros(len(X)),
                          num_views=num_views, units='m')   # the subject is in m


def render_views(scene, cameras, backgrounds, outlines, t, root):
    """The V images (H, W, 3) uint8 of instant t."""
    return [scene.render(v, t, cam, backgrounds[v], outlines[v][0][t], outlines[v][1][t],
                         outlines[v][2][t], root=root[t])
            for v, cam in enumerate(cameras)]


def synthesize(config, out, progress=True):
    """Write the recording described by `config` into folder `out`; returns SynthResult."""
    from tqdm import tqdm

    from monet_ros.io import BagWriter

    start = time.perf_counter()
    out = _check_output(out)
    p = plan(config)
    cameras = p['cameras']
    render_config = RenderConfig(noise=config.noise)
    scene = Scene(cameras, p['parts'], seed=config.seed, config=render_config)
    backgrounds = [scene.background(cam) for cam in cameras]
    outlines = [capsule_outlines(cam, p['A'], p['B'], p['radii'], scene.light,
                                 render_config.levels, render_config.samples,
                                 render_config.axis_points) for cam in cameras]
    num_views = p['in_image'].sum(axis=1)                              # (T, C)
    stamps = p['stamps']
    bag_path = out / 'recording'
    with BagWriter(bag_path) as bag:
        bag.write_tf_static(int(stamps[0]), cameras, parent=FRAME_ID)
        frames = tqdm(range(config.frames), desc='monet synth', unit='frame',
                      file=sys.stderr, disable=not progress, dynamic_ncols=True)
        for t in frames:
            images = render_views(scene, cameras, backgrounds, outlines, t, p['root'])
            write_frame(bag, cameras, int(stamps[t]), images, p['keypoints3d'][t],
                        num_views[t])
    save_rig(out / 'rig.yaml', cameras, frame_id=FRAME_ID)
    labelled = np.flatnonzero(p['labelled'])
    points = np.where(p['label_mask'][labelled][..., None], p['keypoints2d'][labelled], np.nan)
    rows = label_rows(stamps[labelled], [c.name for c in cameras], p['skeleton'].keypoints,
                      points)
    if config.label_subjects and config.subjects > 1:
        rows = subject_label_rows(p, labelled, config.label_occluded)
    rows = write_labels(out / 'labels.csv', rows)
    np.savez_compressed(
        out / 'ground_truth.npz', stamps=stamps, keypoints3d=p['keypoints3d'],
        keypoints2d=p['keypoints2d'], in_image=p['in_image'], occluded=p['occluded'],
        labelled=p['labelled'], camera_names=np.array([c.name for c in cameras]),
        keypoint_names=np.array(p['skeleton'].keypoints),
        **({} if config.subjects == 1 else {
            k: p[k] for k in ('subjects_keypoints3d', 'subjects_keypoints2d',
                              'subjects_in_image', 'subjects_occluded')}))
    if config.subjects > 1:
        write_instances_table(out / 'points2d.csv', p, config.seed)
    bag_bytes = sum(f.stat().st_size for f in bag_path.iterdir())
    result = SynthResult(out=out, frames=config.frames, cameras=len(cameras),
                         keypoints=p['skeleton'].num_keypoints,
                         labelled_instants=len(labelled), label_rows=rows,
                         wall_s=time.perf_counter() - start, bag_bytes=bag_bytes)
    (out / 'README.md').write_text(readme_text(config, p, result))
    return result


def readme_text(config, p, result):
    """The DIR/README.md summary."""
    cams = p['cameras']
    inside = p['in_image']
    hidden = p['occluded'] & inside
    labelled = np.flatnonzero(p['labelled'])
    stamps = p['stamps']
    visible_pct = 100 * inside.mean(axis=(0, 2))
    hidden_pct = 100 * hidden.sum(axis=(0, 2)) / np.maximum(1, inside.sum(axis=(0, 2)))
    rows = '\n'.join(
        f'| {c.name} | {c.width}x{c.height} | {c.K[0, 0]:.1f} | '
        f'{", ".join(f"{d:.4f}" for d in c.dist)} | '
        f'{", ".join(f"{x:.2f}" for x in c.center)} | '
        f'{visible_pct[i]:.1f}% | {hidden_pct[i]:.1f}% |'
        for i, c in enumerate(cams))
    shown = ', '.join(str(stamps[i]) for i in labelled[:20])
    if len(labelled) > 20:
        shown += ' ...'
    occluded_note = ('every keypoint that projects inside the image, including keypoints '
                     'hidden by other limbs' if config.label_occluded else
                     'only keypoints that project inside the image and are not hidden by '
                     'another limb')
    settings = '\n'.join(f'- {k}: {v}' for k, v in config.to_dict().items())
    motion = '' if config.motion_seed is None else f' (motion seed {config.motion_seed})'
    labels_text = ("The ground-truth topic is subject 0's, `labels.csv` labels every "
                   'subject (its `subject` column: the slot in\n`ground_truth.npz`); '
                   if config.label_subjects else
                   "The ground-truth topic and\n`labels.csv` are subject 0's; ") + \
        '`ground_truth.npz` adds subjects_keypoints3d (T, S, C, 3),'
    one = config.subjects == 1
    body = (f"a {p['subject'].body}" if one else f"{config.subjects} {p['subject'].body}s")
    paths = 'a curved path' if one else 'their own curved paths'
    label_columns = ('stamp_ns,camera,keypoint,u,v' + (',subject' if config.label_subjects
                                                        and not one else ''))
    gt_more = ('' if one else '; subjects_keypoints3d (T, S, C, 3), subjects_keypoints2d '
               '(T, V, S, C, 2), subjects_in_image and subjects_occluded (T, V, S, C) (below)')
    several = '' if config.subjects == 1 else f"""
## Several subjects

{config.subjects} subjects walk rings of {', '.join(f'{r:g}' for r in
PATH_RADII[:config.subjects])} m and pass (and hide) each other. {labels_text}
subjects_keypoints2d (T, V, S, C, 2), subjects_in_image and subjects_occluded (T, V, S, C)
(subject s = identity s); `points2d.csv` holds their visible keypoints per camera with a
`subject` column of instance labels shuffled per camera and frame:

```bash
monet triangulate {result.out}/points2d.csv --rig {result.out}/rig.yaml \\
    --subjects {config.subjects} --fps {config.fps:g} --skeleton {config.skeleton} \\
    --out {result.out}/subjects3d
```
"""
    return f"""# Synthetic MONET recording

Rendered by `monet synth` (monet_ros): a calibrated {config.layout} rig of {len(cams)} cameras
around {body} ({p['skeleton'].name}, {p['skeleton'].num_keypoints} keypoints)
walking on {paths}. Seed {config.seed}{motion}; the same settings give byte-identical
message data.

- Frames: {config.frames} instants at {config.fps:g} fps, stamps {stamps[0]} ..
  {stamps[-1]} ns; images {config.width}x{config.height} rgb8.
- Labelled instants: {len(labelled)} of {config.frames}
  ({100 * len(labelled) / config.frames:.2f}%), {result.label_rows} 2D labels in
  `labels.csv`: {occluded_note}, in every view of a labelled instant.
- Labelled stamps: {shown}
- Bag: {result.bag_bytes / 1e6:.1f} MB; rendered in {result.wall_s:.1f} s.

## Files

- `recording/`: rosbag2 (MCAP) with `/camK/image_raw` (sensor_msgs/Image rgb8),
  `/camK/camera_info`, `/tf_static` (world -> camK_optical) and
  `{GROUND_TRUTH_TOPIC}` (sensor_msgs/PointCloud2, fields x y z confidence
  reprojection_error num_views keypoint; num_views = views where it is in the image).
- `rig.yaml`: the cameras (x ~ K (R X + t), OpenCV distortion), frame `world`.
- `labels.csv`: `{label_columns}` in original image pixels
  (`monet_ros.labels.read_labels`).
- `ground_truth.npz`: stamps (T,), keypoints3d (T, C, 3) m, keypoints2d (T, V, C, 2) px,
  in_image and occluded (T, V, C), labelled (T,), camera_names, keypoint_names{gt_more}.

## Cameras

| camera | size | fx | distortion | centre (m) | keypoints in image | of those occluded |
|---|---|---|---|---|---|---|
{rows}

## Use

```bash
monet train {result.out} --out {result.out}/train_monet --skeleton {config.skeleton} --mode monet
monet eval {result.out}/train_monet/model.pt --data {result.out} --out {result.out}/eval \\
    --skeleton {config.skeleton}
```

(`monet train --help` / `monet eval --help` list the options; the folder's rig.yaml,
labels.csv and ground_truth.npz are found automatically.)

{several}
## Settings

{settings}
"""
