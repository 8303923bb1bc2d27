"""Keypoint skeletons: names, bones and left/right symmetry, loaded from YAML (no ROS).

File format (config/skeletons/*.yaml)::

    name: human14
    keypoints: [head, neck, ...]          # order = heatmap channel order
    bones: [[head, neck], ...]            # pairs of keypoint names
    symmetric: [[l_shoulder, r_shoulder], ...]   # optional left/right pairs
"""
from dataclasses import dataclass
from pathlib import Path

import yaml

from monet_ros.share import share_path


class SkeletonError(ValueError):
    """A skeleton file or definition is malformed; the message names the file and field."""


@dataclass(frozen=True)
class Skeleton:
    name: str
    keypoints: tuple
    bones: tuple = ()
    symmetric: tuple = ()

    def __post_init__(self):
        names = list(self.keypoints)
        if not names:
            raise SkeletonError(f'skeleton {self.name!r}: field keypoints is empty')
        if len(set(names)) != len(names):
            raise SkeletonError(f'skeleton {self.name!r}: field keypoints has duplicate names')
        for field in ('bones', 'symmetric'):
            for pair in getattr(self, field):
                if len(pair) != 2 or any(k not in names for k in pair):
                    raise SkeletonError(
                        f'skeleton {self.name!r}: field {field} has {list(pair)!r}, '
                        f'which is not a pair of known keypoints')

    @property
    def num_keypoints(self):
        return len(self.keypoints)

    def index(self, keypoint):
        return self.keypoints.index(keypoint)

    @property
    def bone_indices(self):
        """(B, 2) list of keypoint index pairs."""
        return [(self.index(a), self.index(b)) for a, b in self.bones]

    @property
    def flip_permutation(self):
        """Channel permutation that swaps left and right keypoints (for mirrored images)."""
        perm = list(range(self.num_keypoints))
        for a, b in self.symmetric:
            i, j = self.index(a), self.index(b)
            perm[i], perm[j] = j, i
        return perm

    def to_dict(self):
        return {'name': self.name, 'keypoints': list(self.keypoints),
                'bones': [list(b) for b in self.bones],
                'symmetric': [list(s) for s in self.symmetric]}


def skeleton_from_dict(data, source='<dict>'):
    if not isinstance(data, dict):
        raise SkeletonError(f'{source}: expected a mapping with keypoints and bones')
    if 'keypoints' not in data:
        raise SkeletonError(f'{source}: missing field keypoints')
    try:
        return Skeleton(
            name=str(data.get('name', Path(str(source)).stem)),
            keypoints=tuple(str(k) for k in data['keypoints']),
            bones=tuple(tuple(b) for b in data.get('bones') or ()),
            symmetric=tuple(tuple(s) for s in data.get('symmetric') or ()))
    except SkeletonError as error:
        raise SkeletonError(f'{source}: {error}') from None
    except TypeError as error:
        raise SkeletonError(f'{source}: malformed field ({error})') from None


def skeleton_path(path_or_name):
    """(Path of the YAML, True when it is a shipped preset): a path as given, or a preset
    name under config/skeletons (e.g. 'human14'). SkeletonError for an unknown preset."""
    path = Path(path_or_name)
    if not path.suffix and not path.exists():
        try:
            return share_path('config', 'skeletons', f'{path_or_name}.yaml'), True
        except FileNotFoundError as error:
            raise SkeletonError(f'skeleton preset {path_or_name!r}: {error}') from None
    return path, False


def load_skeleton(path_or_name):
    """A Skeleton from a YAML path, or a preset name under config/skeletons (e.g. 'human14')."""
    path = skeleton_path(path_or_name)[0]
    if not path.is_file():
        raise SkeletonError(f'{path}: skeleton file not found')
    from monet_ros.geometry.rig_fields import safe_yaml
    try:
        data = safe_yaml(path.read_text())          # no aliases: no alias bombs
    except yaml.YAMLError as error:
        raise SkeletonError(f'{path}: not valid YAML ({error})') from None
    return skeleton_from_dict(data, source=path)
