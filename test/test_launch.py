"""launch/pipeline.launch.py with the real `launch` / `launch_ros` (not in the pip wheels:
installed from their jazzy sources by hand, see README); skipped without them. The run of
the launch file on the installed package is in test_package_build.py."""
from pathlib import Path

import pytest

launch = pytest.importorskip('launch', reason='launch (ros2/launch) is not installed')
pytest.importorskip('launch_ros.actions', reason='launch_ros (ros2/launch_ros) is not '
                    'installed')
from launch.launch_description_sources import PythonLaunchDescriptionSource  # noqa: E402
from launch_ros.actions import Node  # noqa: E402


def fake_prefix(tmp_path, repo_root):
    """An ament prefix whose share/monet_ros/config is the checkout's (for the import)."""
    prefix = tmp_path / 'prefix'
    marker = prefix / 'share/ament_index/resource_index/packages/monet_ros'
    marker.parent.mkdir(parents=True)
    marker.write_text('')
    (prefix / 'share/monet_ros').mkdir()
    (prefix / 'share/monet_ros/config').symlink_to(repo_root / 'config')
    return prefix


def test_launch_file_declares_its_arguments_and_nodes(repo_root, tmp_path, monkeypatch):
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(fake_prefix(tmp_path, repo_root)))
    source = PythonLaunchDescriptionSource(str(repo_root / 'launch/pipeline.launch.py'))
    description = source.get_launch_description(launch.LaunchContext())
    arguments = {a.name: a for a in description.get_launch_arguments()}
    assert set(arguments) == {'bag', 'rig', 'model', 'namespace', 'transport', 'debug_image',
                              'use_sim_time', 'slop_ms', 'rate', 'precision', 'backend',
                              'device', 'subjects'}
    context = launch.LaunchContext()
    defaults = {name: ''.join(s.perform(context) for s in a.default_value)
                for name, a in arguments.items() if name not in ('model', 'rig')}
    assert defaults == {'bag': '', 'namespace': 'monet', 'transport': 'auto',
                        'debug_image': 'false', 'use_sim_time': 'false', 'slop_ms': '0.0',
                        'rate': '1.0', 'precision': 'auto', 'backend': 'torch',
                        'device': '', 'subjects': '1'}
    nodes = [e for e in description.entities if isinstance(e, Node)]
    assert sorted(n.node_executable for n in nodes) == ['detector', 'fusion', 'player']
    for node in nodes:
        # each node reads its config/<node>.yaml (launch_ros keeps it as a ParameterFile)
        files = [p.param_file for p in node._Node__parameters if hasattr(p, 'param_file')]
        path = ''.join(s.perform(context) for s in files[0])
        assert Path(path).name == f'{node.node_executable}.yaml' and Path(path).is_file()
