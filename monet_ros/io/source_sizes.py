"""The record `monet import videos` leaves in a recording's folder (`monet_import.yaml`):
each camera's source video size and the size of its recorded images (`--resize`), so that
labels made on the videos (DeepLabCut, SLEAP, ... work on the videos) are brought to the
recording's pixels by `monet labels import` (no ROS).

    # written by monet import videos: the source videos' size of each camera
    resize: 0.5
    cameras:
      back: {source: session/back.mp4, source_size: [1280, 1024], size: [640, 512]}

A video pixel maps to the recording's as cv2.resize maps it (geometry.crop_transform of the
full frame: u' = (u + 0.5) W / W0 - 0.5, likewise v), the mapping the import applied to K.
"""
from pathlib import Path

import numpy as np
import yaml

RECORD = 'monet_import.yaml'


class SourceSizeError(ValueError):
    """A record that cannot be read; the message names the file and field."""


def write_source_sizes(folder, resize, cameras):
    """Write folder/monet_import.yaml. cameras: {name: (source path, (W0, H0) source size,
    (W, H) recorded size)}."""
    data = {'resize': float(resize), 'cameras': {
        name: {'source': str(source), 'source_size': [int(v) for v in source_size],
               'size': [int(v) for v in size]}
        for name, (source, source_size, size) in cameras.items()}}
    text = ("# written by monet import videos: the source videos' size of each camera "
            '(labels made on the videos are scaled by monet labels import)\n'
            + yaml.safe_dump(data, sort_keys=False, default_flow_style=None))
    (Path(folder) / RECORD).write_text(text)


def read_source_sizes(bag):
    """(resize, {camera: ((W0, H0), (W, H))}) of the record beside a recording (its rosbag2
    folder, or the folder of a bare .mcap), or None when there is none. Raises
    SourceSizeError naming the file and field of a malformed record."""
    bag = Path(bag)
    path = (bag if bag.is_dir() else bag.parent) / RECORD
    if not path.is_file():
        return None
    try:
        data = yaml.safe_load(path.read_text())
        resize = float(data['resize'])
        cameras = {}
        for name, entry in data['cameras'].items():
            sizes = tuple(tuple(int(v) for v in entry[key]) for key in ('source_size', 'size'))
            if any(len(s) != 2 or min(s) <= 0 for s in sizes):
                raise ValueError(f'camera {name}: sizes must be [width, height] > 0')
            cameras[str(name)] = sizes
    except (yaml.YAMLError, KeyError, TypeError, ValueError, AttributeError) as error:
        raise SourceSizeError(f'{path}: not a monet import record ({type(error).__name__}: '
                              f'{error})') from None
    return resize, cameras


def video_to_recording(cameras):
    """{camera: 3x3 S} mapping a source video's pixels to the recorded images' for every
    camera whose size changed (cameras: read_source_sizes' dict)."""
    from monet_ros.geometry import crop_transform
    return {name: crop_transform((0, 0, *source), size)
            for name, (source, size) in cameras.items() if tuple(source) != tuple(size)}


def uniform_scale(scale):
    """3x3 S of labels at 1 / scale the recording's size: u' = (u + 0.5) scale - 0.5."""
    return np.array([[scale, 0.0, 0.5 * scale - 0.5], [0.0, scale, 0.5 * scale - 0.5],
                     [0.0, 0.0, 1.0]])


def scale_label_rows(rows, transforms, camera_map=None):
    """The LabelRows with u, v mapped by transforms[camera] (3x3 S; a camera without one is
    kept; `None` key: every camera). camera_map: label camera -> recording camera names."""
    from dataclasses import replace
    camera_map = camera_map or {}
    out = []
    for row in rows:
        S = transforms.get(camera_map.get(row.camera, row.camera), transforms.get(None))
        if S is None:
            out.append(row)
            continue
        out.append(replace(row, u=float(S[0, 0] * row.u + S[0, 2]),
                           v=float(S[1, 1] * row.v + S[1, 2])))
    return out
