"""Group synchronised camera views of a bag into multiview frames by header stamp."""
from dataclasses import dataclass, field

from .images import any_image_to_numpy


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


def iter_multiview_frames(reader, image_topics, slop_ns=0, rig=None, decode=True,
                          max_pending=64):
    """Yield MultiviewFrame for every instant seen on any of the image topics.

    reader: a BagReader; image_topics: list of Image / CompressedImage topics (camera name
    = the topic's first name, or the rig camera whose `topic` matches) or a dict
    camera -> topic. Views are grouped by header stamp: exactly (slop_ns=0) or with the
    nearest stamp within slop_ns. A frame lacking views is still yielded with `missing`
    listing them; views that fail to decode are missing too and counted in reader.report.
    A frame is yielded once it is complete, or once every missing camera's stream has moved
    past its stamp + slop, or when more than max_pending frames wait (bounded memory).
    decode=False gives the messages themselves in `images`.
    """
    topic_to_cam = _topic_map(image_topics, rig)
    cams = list(dict.fromkeys(topic_to_cam.values()))
    known = set(reader.topics)
    # cameras whose topic the bag does not have never hold frames back (only knowable when
    # the bag lists its topics: metadata.yaml or intact summaries)
    absent = {topic_to_cam[t] for t in topic_to_cam
              if t not in known and getattr(reader, 'topics_complete', True)}
    rig_by_name = {c.name: c for c in rig} if rig is not None else None
    slop_ns = int(slop_ns)
    last_stamp = {c: None for c in cams}
    pending = []              # [stamp, {cam: BagMessage}] sorted by stamp

    def passed(group):
        stamp, views = group
        for c in cams:
            if c in views or c in absent:
                continue
            if last_stamp[c] is None or last_stamp[c] <= stamp + slop_ns:
                return False
        return True

    def emit(group):
        stamp, views = group
        images, stamps, missing = {}, {}, []
        for c in cams:
            m = views.get(c)
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
        return MultiviewFrame(stamp, images, missing, stamps, cameras)

    for m in reader.messages(topics=list(topic_to_cam)):
        cam = topic_to_cam[m.topic]
        try:
            s = m.stamp_ns
        except (AttributeError, TypeError, ValueError) as exc:   # schema without a header
            reader.report.skip(m.topic, f'no usable header stamp: {exc}')
            continue
        last_stamp[cam] = s if last_stamp[cam] is None else max(last_stamp[cam], s)
        best, best_d = None, None
        for group in pending:
            d = abs(group[0] - s)
            if d <= slop_ns and cam not in group[1] and (best is None or d < best_d):
                best, best_d = group, d
        if best is None:
            k = len(pending)
            while k > 0 and pending[k - 1][0] > s:
                k -= 1
            pending.insert(k, [s, {cam: m}])
        else:
            best[1][cam] = m
        while pending and (len(pending[0][1]) == len(cams) or passed(pending[0])
                           or len(pending) > max_pending):
            yield emit(pending.pop(0))
    while pending:
        yield emit(pending.pop(0))
