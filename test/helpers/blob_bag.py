"""Write a blob Recording as a `monet synth`-style folder: rosbag2 + rig.yaml + labels.csv +
ground_truth.npz (with the project's own writers)."""
from pathlib import Path

import numpy as np

from monet_ros.geometry import save_rig
from monet_ros.io import BagWriter
from monet_ros.labels import label_rows, write_labels


def write_blob_folder(recording, out, camera_info=False):
    """camera_info: also write /camK/camera_info beside every image (for the player)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    cams = [c.replace(topic=f'/{c.name}/image_raw') for c in recording.cameras]
    save_rig(out / 'rig.yaml', cams)
    with BagWriter(out / 'recording') as bag:
        for t, stamp in enumerate(recording.stamps):
            for cam, frames in zip(cams, recording.frames):
                bag.write_image(cam.topic, int(stamp), frames[t], f'{cam.name}_optical')
                if camera_info:
                    bag.write_camera_info(f'/{cam.name}/camera_info', int(stamp), cam,
                                          f'{cam.name}_optical')
    labelled = recording.labelled_instants
    write_labels(out / 'labels.csv', label_rows(
        recording.stamps[labelled], [c.name for c in cams], recording.keypoints,
        recording.labels[labelled]))
    np.savez_compressed(out / 'ground_truth.npz', stamps=recording.stamps,
                        keypoints3d=recording.gt3d)
    return out
