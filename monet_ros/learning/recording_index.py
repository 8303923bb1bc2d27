"""The instants of a recording without decoding its images: cameras, image topics, stamps
and which instants are complete (`monet info`, `monet labels import`, `monet eval
--reference`, the labelling app)."""
from dataclasses import dataclass

import numpy as np


@dataclass
class RecordingIndex:
    """bag path; cameras (Camera list); topics {camera: image topic}; stamps (T,) int64 ns
    of every instant; complete (T,) bool (every camera has a view); reader (BagReader)."""
    bag: object
    cameras: list
    topics: dict
    stamps: np.ndarray
    complete: np.ndarray
    reader: object
    notes: list = None


def image_topic(reader, cam):
    """The image topic of a camera in the bag: its rig topic or /<name>/image_raw, or that
    topic + '/compressed' when only the compressed one was recorded."""
    topic = cam.topic or f'/{cam.name}/image_raw'
    if topic not in reader.topics and topic + '/compressed' in reader.topics:
        topic += '/compressed'
    return topic


def recording_index(path, rig=None, slop_ns=0, camera_map=(), rig_units=None):
    """RecordingIndex of a recording (rosbag2 folder, .mcap, or `monet synth` folder), read
    without decoding images. A rig file's cameras are renamed by camera_map and fitted to
    the images (io.rig_fit; `notes` says how); rig_units: the length unit of a rig file
    that states none (geometry.read_rig). Raises RecordingError naming the bag when it
    has no instant."""
    from monet_ros.io import iter_multiview_frames, open_bag, rig_from_bag
    from monet_ros.learning.recording import RecordingError, find_recording_parts

    parts = find_recording_parts(path)
    reader = open_bag(parts['bag'])
    cameras = list(rig_from_bag(reader, rig_file=rig or parts['rig'], units=rig_units))
    notes = []
    if rig or parts['rig']:
        from monet_ros.io.rig_fit import fit_rig_to_bag
        cameras, notes = fit_rig_to_bag(cameras, reader, camera_map)
    topics = {c.name: image_topic(reader, c) for c in cameras}
    stamps, complete = [], []
    for frame in iter_multiview_frames(reader, topics, slop_ns=slop_ns, decode=False):
        stamps.append(int(frame.stamp_ns))
        complete.append(not frame.missing)
    if not stamps:
        raise RecordingError(f'{parts["bag"]}: no image on {sorted(topics.values())}')
    return RecordingIndex(parts['bag'], cameras, topics, np.array(stamps, np.int64),
                          np.array(complete, bool), reader, notes)
