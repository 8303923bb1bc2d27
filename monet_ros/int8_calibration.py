"""precision int8 calibrated on the crops the run will make (no ROS): one rule for `monet
process`, `monet pipeline` and the detector node.

An int8 quant's activation ranges follow the crops it was calibrated on, so a run
calibrates on its own crop mode (models.quantize's calibration rule):
- tracked runs (the default: `monet process`, `monet pipeline`, the detector node with
  track true) on tracked crops: the float32 network runs over instants of the calibration
  recording with the tracked rule of monet_ros.crop_rule (TrackedCrops: full frame first,
  then around the projection of the fused 3D), and the crops the rule makes once the 3D is
  found are the calibration set (tracked_crops);
- full-frame runs (`--no-track`, track false) on full-frame crops
  (models.quantize.calibration_crops);
- the detector node with track false and a fixed `box` on that box's crops;
- `monet process --subjects N` (tracked) on the crops a several-subject run makes
  (subject_crops: each subject's crop around its track, and the discovery maps: the whole
  frame or its tiles).
The crops key ('full', 'tracked-m<margin>-t<trim>-k<min_points>',
'box-<x0>_<y0>_<x1>_<y1>' or 'subjects<N>-d<tiles>-m<margin>-t<trim>-k<min_points>':
crops_key) names the cached quant
(`<model>.<sha256[:16]>.<key>.int8.onnx`), so each crop mode of one checkpoint has its
quant and none is used for another; new weights need a new one.
Measured on the Pose2Sim recording: bench/results/int8_accuracy.md.
"""
import os

import numpy as np

from monet_ros.crop_rule import TrackedCrops, TrackedRule
from monet_ros.fusion import FusionConfig, fuse_heatmaps
from monet_ros.models.crop import crop_images
from monet_ros.models.quantize import (
    CALIBRATION_IMAGES,
    FULL_CROPS,
    INT8_SUFFIX,
    Int8Error,
    calibration_crops,
)

# passes of the float32 network per calibration instant: full frame, then tracked around
# that 3D; the crops calibrated on are the rule's around the second pass's 3D
PASSES = 2
# subject_crops: the instant is given to its SubjectsStep as PASSES frames this far apart
# (30 fps), the subject crops kept are those of the frame after them
PERIOD_NS = 33_333_333


def crops_key(track, rule=None, box=None, subjects=None):
    """The crops key of a run: 'tracked-m<margin>-t<trim>-k<min_points>' of its
    crop_rule.TrackedRule (None = the defaults) when it tracks, else 'full', or with a fixed
    `box` (x0, y0, x1, y1) 'box-<x0>_<y0>_<x1>_<y1>'; a tracked run of several subjects
    (`subjects` a subjects.detection.SubjectsConfig with subjects N >= 2: `monet process
    --subjects N`) 'subjects<N>-d<discovery_tiles>-m<margin>-t<trim>-k<min_points>'
    (subject_crops). Everything of the rule that moves the crops is in the key; the
    timeout and a tracked run's fallback box are not (they only decide the crops before
    the subject is found)."""
    if not track:
        if box is not None and len(box):
            return 'box-' + '_'.join(f'{float(v):g}' for v in box)
        return FULL_CROPS
    rule = rule or TrackedRule()
    tail = f'm{rule.margin:g}-t{rule.trim:g}-k{rule.min_points}'
    if subjects is not None and subjects.subjects > 1:
        return f'subjects{subjects.subjects}-d{subjects.discovery_tiles}-{tail}'
    return f'tracked-{tail}'


def _instants(recording, cameras, per_instant, count, slop_ns, what):
    """(present Cameras, RGB images) of instants of `recording` taken evenly over it,
    ceil(count / per_instant) of them (the calibration's: tracked_crops, subject_crops),
    views that do not decode left out, instants whose images are not the rig's size
    skipped. cameras: the rig cameras (None = the recording's camera_info + /tf_static).
    Raises Int8Error as tracked_crops (`what`: the crops named in the message)."""
    from monet_ros.io import any_image_to_numpy, open_bag
    from monet_ros.io.images import to_rgb8
    from monet_ros.io.multiview import image_topics, iter_multiview_frames
    from monet_ros.rig_select import load_node_rig

    try:
        if cameras is None:
            cameras, _ = load_node_rig(recording)
        reader = open_bag(recording)
        topics = image_topics(reader, cameras, recording)
    except (OSError, ValueError) as error:
        raise Int8Error(f'calibration {recording}: {what} need its images and rig '
                        f'(camera_info + /tf_static) ({error})') from None
    if len(cameras) < 2:
        raise Int8Error(f'calibration {recording}: {what} need at least 2 cameras, '
                        f'found {len(cameras)}')
    by_name = {c.name: c for c in cameras}
    counts = [int(getattr(reader.topics[t], 'count', 0) or 0) for t in topics.values()]
    instants = -(-count // per_instant(len(cameras)))
    every = max(1, min(counts) // instants) if min(counts) else 1
    try:
        frames = iter_multiview_frames(reader, topics, slop_ns=slop_ns, decode=False)
        for n, frame in enumerate(frames):
            if n % every:
                continue
            present, images = [], []
            for name, message in frame.images.items():
                try:
                    images.append(to_rgb8(any_image_to_numpy(message.msg)))
                except ValueError:
                    continue          # a view that does not decode: not calibration data
                present.append(by_name[name])
            if not present or any(i.shape[:2] != (c.height, c.width)
                                  for i, c in zip(images, present)):
                continue
            yield present, images
    except (OSError, ValueError) as error:
        raise Int8Error(f'calibration {recording}: cannot read it ({error})') from None


def tracked_crops(recording, detector, rule=None, cameras=None, count=CALIBRATION_IMAGES,
                  slop_ns=0, fusion=None):
    """Up to `count` network-input crops (N, H, W, 3) uint8 RGB that the tracked rule makes
    around the subject on instants of `recording` (the calibration set of tracked runs).

    recording: rosbag2 folder or .mcap; detector: a float32 (or bfloat16) models.Detector
    of the network to quantise; rule: crop_rule.TrackedRule (None = the defaults);
    cameras: the rig cameras of the run (None = the recording's camera_info + /tf_static);
    slop_ns: stamp tolerance between views; fusion: FusionConfig (None = the defaults).
    Instants are taken evenly over the recording (ceil(count / views) of them); on each the
    detector runs on full frames, its heatmaps are fused to 3D, it runs again on the
    rule's crops around that 3D, and the rule's crops around the new 3D are kept (a
    subject that does not move between instants: the crops a tracked run makes once it
    has found it). Views without enough 3D keypoints projecting into them keep the full
    frame, as the rule does. Raises Int8Error (one line, naming the recording) when it
    cannot be read, has no rig or fewer than 2 cameras with images, or no instant decodes."""
    rule = rule or TrackedRule()
    fusion = fusion or FusionConfig()
    h, w = detector.input_size
    crops = []
    try:
        for present, images in _instants(recording, cameras, lambda V: V, count, slop_ns,
                                         'tracked crops'):
            boxes = _tracked_boxes(detector, images, present, rule, fusion)
            crops.extend(crop_images(images, boxes, (w, h)))
            if len(crops) >= count:
                break
    except Int8Error:
        raise                                         # _instants': one line already
    except (OSError, ValueError) as error:
        raise Int8Error(f'calibration {recording}: cannot read it ({error})') from None
    if not crops:
        raise Int8Error(f"calibration {recording}: no instant decodes at the rig's image size")
    return np.stack(crops[:count])


def subject_crops(recording, detector, subjects, rule=None, cameras=None,
                  count=CALIBRATION_IMAGES, slop_ns=0, association=None, tracker=None):
    """Up to `count` network-input crops (N, H, W, 3) uint8 RGB of the kinds `monet process
    --subjects N` makes (the calibration set of its int8 runs): on instants of `recording`
    taken evenly over it (ceil(count / (V (N + 1))) of them), a fresh
    subjects.detection.SubjectsStep (the float32 `detector`, `subjects` a SubjectsConfig,
    association / tracker / rule as the run's) runs the instant as PASSES frames
    (discovery and the crops around what it found, then the crops around the tracks: a
    subject that does not move) and the crop rule's box around each track's prediction for
    the next frame is kept (the subject crops of a tracked frame: N per view at most), plus,
    per view, one of its discovery maps (subjects.detection.discovery_boxes: the whole
    frame or one of its tiles, the next tile at each instant). Arguments and errors as
    tracked_crops."""
    from monet_ros.subjects.detection import SubjectsStep, discovery_boxes

    h, w = detector.input_size
    N = subjects.subjects
    crops = []
    try:
        for n, (present, images) in enumerate(_instants(
                recording, cameras, lambda V: V * (N + 1), count, slop_ns, 'subject crops')):
            step = SubjectsStep(detector, present[0].units, subjects, association, tracker,
                                rule)
            for k in range(PASSES):           # discovery, then the crops around its 3D
                step.step(images, present, k * PERIOD_NS)
            boxes = step.crop_boxes(present, step.hypotheses(PASSES * PERIOD_NS))  # (V, H, 4)
            v_idx, h_idx = np.nonzero(np.isfinite(boxes).all(-1))
            views = v_idx.tolist()
            chosen = [detector.boxes_for([present[v] for v in views], boxes[v_idx, h_idx])]
            for v, tiles in enumerate(discovery_boxes(detector, present,
                                                      subjects.discovery_tiles)):
                views.append(v)
                chosen.append(tiles[n % len(tiles)][None])
            crops.extend(crop_images([images[v] for v in views],
                                     np.concatenate(chosen).reshape(-1, 4), (w, h)))
            if len(crops) >= count:
                break
    except Int8Error:
        raise                                         # _instants': one line already
    except (OSError, ValueError) as error:
        raise Int8Error(f'calibration {recording}: cannot read it ({error})') from None
    if not crops:
        raise Int8Error(f"calibration {recording}: no instant decodes at the rig's image size")
    return np.stack(crops[:count])


def _tracked_boxes(detector, images, cameras, rule, fusion):
    """The boxes (V, 4) the tracked rule crops one instant with once it has its 3D."""
    tracker = TrackedCrops(rule, units=cameras[0].units)
    for _ in range(PASSES):
        boxes = detector.boxes_for(cameras, tracker.boxes(cameras))
        heat, heat_cameras = detector.predict(images, cameras, boxes, keep_aspect=False)
        if len(cameras) >= 2:
            result = fuse_heatmaps(heat, np.stack([c.K for c in heat_cameras]), cameras,
                                   fusion)
            tracker.update(result.X)
    return detector.boxes_for(cameras, tracker.boxes(cameras))


def int8_calibration(calibration, track, rule=None, cameras=None, slop_ns=0, fusion=None,
                     box=None, subjects=None, association=None, tracker=None):
    """(crops key, calibration) to give models.Detector (int8_crops=, calibration=) for a
    run with tracking `track` (and its TrackedRule `rule`; without tracking, its fixed
    `box` when it has one).

    calibration: a recording (rosbag2 folder or .mcap), a cached quant (`*.int8.onnx`), crops
    (N, H, W, 3) uint8, or None / '' (the cached quant must exist). A recording of a
    tracked run becomes a function detector -> tracked_crops(recording, detector, rule,
    cameras, slop_ns=slop_ns, fusion=fusion), which the Detector calls with a float32
    detector of the network only when no quant of that key is cached; anything else is
    given as it is (a recording of a full-frame run: its full-frame crops,
    models.quantize.calibration_crops), but a recording of a fixed-box run becomes a
    function detector -> that box's crops of it. The functions are RecordingCrops, whose
    `recording` the Detector checks first, cached quant or not (a missing path, or one that
    is no recording, is refused the same either way: models.quantize.check_calibration).
    subjects: a subjects.detection.SubjectsConfig with subjects >= 2 (a tracked run of
    several subjects, `monet process --subjects N`, with its association / tracker
    configs): a recording becomes a function detector -> subject_crops of it, under the
    subjects crops key."""
    key = crops_key(track, rule, box, subjects)
    recording = isinstance(calibration, (str, os.PathLike)) and str(calibration) != '' \
        and not str(calibration).endswith(INT8_SUFFIX)
    if not recording or key == FULL_CROPS:
        return key, calibration
    if not track:
        return key, RecordingCrops(calibration, lambda detector: calibration_crops(
            calibration, detector.input_size, box=box))
    if subjects is not None and subjects.subjects > 1:
        return key, RecordingCrops(calibration, lambda detector: subject_crops(
            calibration, detector, subjects, rule, cameras, slop_ns=slop_ns,
            association=association, tracker=tracker))
    return key, RecordingCrops(calibration, lambda detector: tracked_crops(
        calibration, detector, rule, cameras, slop_ns=slop_ns, fusion=fusion))


class RecordingCrops:
    """The calibration crops of `recording` for one crop mode: called with a float32
    models.Detector of the network, `make(detector)` -> (N, H, W, 3) uint8. `recording` is
    what models.quantize checks (check_recording) before looking for a cached quant, and
    names in the note of the quant it writes."""

    def __init__(self, recording, make):
        self.recording = recording
        self.make = make

    def __call__(self, detector):
        return self.make(detector)
