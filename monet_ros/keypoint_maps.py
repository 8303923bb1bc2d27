"""Shipped keypoint name maps (config/keypoint_maps/*.yaml): the marker names of common
pose models -> a skeleton of config/skeletons, selectable by name wherever a
--keypoint-map is taken (`--keypoint-map body25b`). No ROS.

    body25   OpenPose BODY_25 (Nose as head)       -> human14
    body25b  OpenPose BODY_25B / Pose2Sim's .trc   -> human14
    coco17   COCO-17 (no neck; nose as head)       -> human14
    halpe26  Halpe-26 / AlphaPose                  -> human14

File format: name, skeleton (the target preset), map {source name: skeleton keypoint}.
Names are renames only (no derived points): a keypoint a set lacks is not scored.
"""
from pathlib import Path

import yaml

from monet_ros.share import share_path


class KeypointMapError(ValueError):
    """A map file or name that cannot be used; the message names it."""


def keypoint_map_names():
    """Names of the shipped maps (file stems), sorted."""
    try:
        folder = share_path('config', 'keypoint_maps')
    except FileNotFoundError:
        return ()
    return tuple(sorted(p.stem for p in Path(folder).glob('*.yaml')))


def load_keypoint_map(name):
    """((source, target), ...) of a shipped map; KeypointMapError naming the map, or the
    file and field, when it is unknown or malformed (targets are checked against the
    map's skeleton)."""
    from monet_ros.geometry.rig_fields import safe_yaml
    from monet_ros.skeleton import SkeletonError, load_skeleton

    names = keypoint_map_names()
    if name not in names:
        raise KeypointMapError(f'keypoint map {name!r} is not one of {", ".join(names)}')
    path = share_path('config', 'keypoint_maps', f'{name}.yaml')
    try:
        data = safe_yaml(Path(path).read_text())
    except (OSError, yaml.YAMLError) as error:
        raise KeypointMapError(f'{path}: cannot read ({error})') from None
    mapping = data.get('map') if isinstance(data, dict) else None
    if not isinstance(mapping, dict) or not mapping:
        raise KeypointMapError(f'{path}: field map: expected {{source: keypoint}} pairs')
    try:
        keypoints = load_skeleton(str(data.get('skeleton', 'human14'))).keypoints
    except SkeletonError as error:
        raise KeypointMapError(f'{path}: field skeleton: {error}') from None
    bad = [str(t) for t in mapping.values() if str(t) not in keypoints]
    if bad:
        raise KeypointMapError(f'{path}: field map: {bad[0]!r} is not a keypoint of '
                               f'{data.get("skeleton")}')
    return tuple((str(s), str(t)) for s, t in mapping.items())


def expand_keypoint_maps(items):
    """--keypoint-map items with shipped map names replaced by their pairs: ('body25b',
    'Nose=nose') -> ('Head=head', ..., 'Nose=nose'); later pairs win. A bare word that is
    not a map name raises KeypointMapError listing the names."""
    if isinstance(items, dict):
        return items
    out = []
    for item in items or ():
        if isinstance(item, (tuple, list)):
            out.append(item)
            continue
        for part in str(item).split(','):
            if not part.strip():
                continue
            if '=' in part:
                out.append(part)
                continue
            if part.strip() not in keypoint_map_names():
                raise KeypointMapError(f'--keypoint-map: {part.strip()!r} is not NAME=NEW_NAME '
                                       f'or a map name ({", ".join(keypoint_map_names())})')
            out += [f'{s}={t}' for s, t in load_keypoint_map(part.strip())]
    return tuple(out)
