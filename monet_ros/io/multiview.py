"""Group synchronised camera views of a bag into multiview frames by header stamp."""
from dataclasses import dataclass, field
import math

from .images import any_image_to_numpy

# How far (stamp time) streams may be logged out of order before a view counts as lost.
REORDER_NS = 1_000_000_000


@dataclass
class MultiviewFrame:
    """Views of one instant. images: camera -> decoded array for the views present;
    missing: cameras with no (decodable) image for this instant, in camera order;
    stamps: camera -> the view's own header stamp (differs from stamp_ns within the slop);
    cameras: camera -> Camera when a rig was given."""
    stamp_ns: int
    images: dict
    missing: list
    stamps: dict = field(default_factory=dict)
    cameras: dict = None


def camera_name_for_topic(topic):
    """'/cam01/image_raw/compressed' -> 'cam01' (the first name of the topic)."""
    parts = [p for p in str(topic).split('/') if p]
    return parts[0] if parts else str(topic)


def _topic_map(image_topics, rig):
    if isinstance(image_topics, dict):
        return {str(t): str(c) for c, t in image_topics.items()}
    topics = [image_topics] if isinstance(image_topics, str) else list(image_topics)
    by_topic = {c.topic: c.name for c in rig or [] if getattr(c, 'topic', None)}
    names = [by_topic.get(t, camera_name_for_topic(t)) for t in topics]
    if len(set(names)) != len(names):
        names = list(topics)                 # ambiguous first names: key by topic
    return dict(zip(topics, names))


def image_topics(reader, cameras, bag=None):
    """camera name -> image topic in the recording, for every camera (ONE rule for `monet
    process`, `monet train` / load_recording and the pipeline's transport): the camera's
    `topic` (default /<name>/image_raw), else the same topic + '/compressed' (or without
    it) when only that one is in the recording. Raises ValueError naming the camera, the
    topics tried and the recording when none is there."""
    known = set(reader.topics)
    topics = {}
    for cam in cameras:
        base = cam.topic or f'/{cam.name}/image_raw'
        raw = base[:-len('/compressed')] if base.endswith('/compressed') else base
        tried = list(dict.fromkeys([base, raw, raw + '/compressed']))
        found = next((t for t in tried if t in known), None)
        if found is None:
            raise ValueError(f'{bag or reader.path}: no image topic for camera {cam.name!r} '
                             f'(tried {", ".join(tried)})')
        topics[cam.name] = found
    return topics


def image_transport(topics):
    """'compressed' when every topic of {camera: topic} is a /compressed one, else 'raw'."""
    topics = list(topics.values()) if isinstance(topics, dict) else list(topics)
    return 'compressed' if topics and all(t.endswith('/compressed') for t in topics) \
        else 'raw'


def iter_multiview_frames(reader, image_topics, slop_ns=0, rig=None, decode=True,
                          max_pending=64, reorder_ns=REORDER_NS):
    """Yield MultiviewFrame for every instant seen on any of the image topics.

    reader: a BagReader; image_topics: list of Image / CompressedImage topics (camera name
    = the topic's first name, or the rig camera whose `topic` matches) or a dict
    camera -> topic. Views are grouped by header stamp with the one rule of
    monet_ros.sync.StampSynchronizer (exactly, slop_ns=0, or with the nearest stamp within
    slop_ns), so the order in which they were logged does not matter within `reorder_ns`
    of stamp time. A frame lacking views is still yielded with `missing` listing them.
    Skipped and counted in reader.report (by topic, with the reason): views that fail to
    decode (also `missing`), views whose camera repeats a stamp it already gave (a driver
    that stamps every image 0: never merged into another instant), views of an instant
    already yielded (late), messages without a header stamp. A frame is yielded once it is
    complete, or once every missing camera's stream has moved past its stamp + slop +
    reorder_ns, or when more than max_pending frames wait (bounded memory).
    decode=False gives the messages themselves in `images`.
    """
    from monet_ros.sync import StampSynchronizer

    topic_to_cam = _topic_map(image_topics, rig)
    cams = list(dict.fromkeys(topic_to_cam.values()))
    known = set(reader.topics)
    # cameras whose topic the bag does not have never hold frames back (only knowable when
    # the bag lists its topics: metadata.yaml or intact summaries)
    absent = {topic_to_cam[t] for t in topic_to_cam
              if t not in known and getattr(reader, 'topics_complete', True)}
    rig_by_name = {c.name: c for c in rig} if rig is not None else None
    sync = StampSynchronizer(cams, slop_ns=int(slop_ns), timeout_s=math.inf, min_keys=1,
                             max_pending=max_pending, reorder_ns=reorder_ns,
                             history=max(64, 2 * max_pending))
    sync.set_expected([c for c in cams if c not in absent])

    def emit(group):
        images, stamps, missing = {}, {}, []
        for c in cams:
            m = group.items.get(c)
            if m is None:
                missing.append(c)
                continue
            if decode:
                try:
                    images[c] = any_image_to_numpy(m.msg)
                except Exception as exc:    # noqa: BLE001 - a bad image costs only its view
                    reader.report.skip(m.topic, f'image decode failed: {exc}')
                    missing.append(c)
                    continue
            else:
                images[c] = m
            stamps[c] = m.stamp_ns
        cameras = None if rig_by_name is None else {c: rig_by_name.get(c) for c in cams}
        return MultiviewFrame(group.stamp_ns, images, missing, stamps, cameras)

    for m in reader.messages(topics=list(topic_to_cam)):
        cam = topic_to_cam[m.topic]
        try:
            s = int(m.stamp_ns)
        except (AttributeError, TypeError, ValueError) as exc:   # schema without a header
            reader.report.skip(m.topic, f'no usable header stamp: {exc}')
            continue
        repeated, late = sync.stats.repeated, sync.stats.late
        groups = sync.add(cam, s, m)
        if sync.stats.repeated > repeated:
            reader.report.skip(m.topic, f'camera {cam} repeats header stamp {s} (the driver '
                               'does not stamp each image): not merged into another instant')
        elif sync.stats.late > late:
            reader.report.skip(m.topic, f'view of an instant already grouped (stamp {s}; '
                               f'logged more than {reorder_ns / 1e9:g} s out of order)')
        for group in groups:
            yield emit(group)
    for group in sync.flush():
        yield emit(group)
