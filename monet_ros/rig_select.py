"""The `rig` and `cameras` parameters / options shared by the nodes and the commands (e.g.
`monet process`): load a rig and select its cameras."""
from pathlib import Path

from monet_ros.config import ConfigError

DEFAULT_FRAME = 'world'


def load_node_rig(path, units=None):
    """(cameras, frame_id) from a rig file (any format geometry.load_rig reads) or from a
    recording (rosbag2 folder or .mcap: its camera_info + /tf_static, whose root frame is
    then the frame, io.rig_and_frame_from_bag). units ('m', 'cm', 'mm' or None / ''): the
    rig's length unit when the file states none (the rig_units parameter, --rig-units)."""
    units = units or None
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f'rig {path}: no such file or folder')
    if path.is_dir() or path.suffix == '.mcap':
        from monet_ros.io.rig import rig_and_frame_from_bag
        cameras, root = rig_and_frame_from_bag(path, units=units)
        return list(cameras), root or DEFAULT_FRAME
    from monet_ros.geometry import read_rig
    cameras, frame_id = read_rig(path, units=units)
    return list(cameras), frame_id or DEFAULT_FRAME


def select_cameras(owner, rig, names, minimum=1):
    """The rig cameras named in `names` (all when empty), in that order; ConfigError for an
    unknown name or fewer than `minimum` cameras."""
    by_name = {cam.name: cam for cam in rig}
    names = list(names) or list(by_name)
    unknown = [n for n in names if n not in by_name]
    if unknown:
        raise ConfigError(owner, 'cameras', f'unknown camera {unknown[0]!r}; the rig has '
                          f'{sorted(by_name)}')
    if len(set(names)) != len(names):
        raise ConfigError(owner, 'cameras', f'duplicate camera names in {names}')
    if len(names) < minimum:
        raise ConfigError(owner, 'cameras', f'needs at least {minimum} cameras, got '
                          f'{len(names)} ({names})')
    return [by_name[n] for n in names]
