"""launch/pipeline.launch.py with the real `launch` / `launch_ros` (not in the pip wheels:
tools/install_launch.sh installs them from their jazzy sources, docs/install.md); skipped
without them. The runs of the launch file on the installed package (one subject, two) are in
test_package_build.py."""
from pathlib import Path

import pytest
import yaml

launch = pytest.importorskip('launch', reason='launch (ros2/launch) is not installed')
pytest.importorskip('launch_ros.actions', reason='launch_ros (ros2/launch_ros) is not '
                    'installed')
from launch.launch_description_sources import PythonLaunchDescriptionSource  # noqa: E402
from launch.substitutions.substitution_failure import SubstitutionFailure  # noqa: E402
from launch_ros.actions import Node  # noqa: E402
from launch_ros.utilities import evaluate_parameters  # noqa: E402


def fake_prefix(tmp_path, repo_root):
    """An ament prefix whose share/monet_ros/config is the checkout's (for the import)."""
    prefix = tmp_path / 'prefix'
    marker = prefix / 'share/ament_index/resource_index/packages/monet_ros'
    marker.parent.mkdir(parents=True)
    marker.write_text('')
    (prefix / 'share/monet_ros').mkdir()
    (prefix / 'share/monet_ros/config').symlink_to(repo_root / 'config')
    return prefix


def launch_description(repo_root, tmp_path, monkeypatch):
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(fake_prefix(tmp_path, repo_root)))
    source = PythonLaunchDescriptionSource(str(repo_root / 'launch/pipeline.launch.py'))
    return source.get_launch_description(launch.LaunchContext())


def node_parameters(description, arguments):
    """{executable: {name: value}} of the launch description's nodes with `arguments`
    (name -> text, as `ros2 launch ... name:=text`; the rest at their defaults): each node's
    config YAML, then the launch file's values over it, as the node receives them."""
    context = launch.LaunchContext()
    for declared in description.get_launch_arguments():
        text = arguments.get(declared.name)
        if text is None:
            text = ''.join(s.perform(context) for s in declared.default_value)
        context.launch_configurations[declared.name] = text
    out = {}
    for node in (e for e in description.entities if isinstance(e, Node)):
        values = {}
        for item in evaluate_parameters(context, node._Node__parameters):
            if isinstance(item, dict):
                values.update(item)
            else:      # a parameter file: /**/<node>: ros__parameters
                values.update(*[v['ros__parameters']
                                for v in yaml.safe_load(Path(item).read_text()).values()])
        out[node.node_executable] = values
    return out


def test_launch_file_declares_its_arguments_and_nodes(repo_root, tmp_path, monkeypatch):
    description = launch_description(repo_root, tmp_path, monkeypatch)
    arguments = {a.name: a for a in description.get_launch_arguments()}
    assert set(arguments) == {'bag', 'rig', 'model', 'namespace', 'transport', 'debug_image',
                              'use_sim_time', 'slop_ms', 'rate', 'precision', 'backend',
                              'device', 'subjects', 'skeleton', 'link_mm', 'discovery_tiles'}
    context = launch.LaunchContext()
    defaults = {name: ''.join(s.perform(context) for s in a.default_value)
                for name, a in arguments.items() if name not in ('model', 'rig')}
    assert defaults == {'bag': '', 'namespace': 'monet', 'transport': 'auto',
                        'debug_image': 'false', 'use_sim_time': 'false', 'slop_ms': '0.0',
                        'rate': '1.0', 'precision': 'auto', 'backend': 'auto',
                        'device': '', 'subjects': '1', 'skeleton': 'human14',
                        'link_mm': '600.0', 'discovery_tiles': '2'}
    nodes = [e for e in description.entities if isinstance(e, Node)]
    assert sorted(n.node_executable for n in nodes) == ['detector', 'fusion', 'player']
    for node in nodes:
        # each node reads its config/<node>.yaml (launch_ros keeps it as a ParameterFile)
        files = [p.param_file for p in node._Node__parameters if hasattr(p, 'param_file')]
        path = ''.join(s.perform(context) for s in files[0])
        assert Path(path).name == f'{node.node_executable}.yaml' and Path(path).is_file()


def test_player_waits_for_the_topics_of_one_subject(repo_root, tmp_path, monkeypatch):
    description = launch_description(repo_root, tmp_path, monkeypatch)
    params = node_parameters(description, {'model': 'm.pt', 'bag': 'rec'})
    assert params['player']['wait_for_topics'] == ['{camera}/heatmaps']
    assert params['detector']['subjects'] == params['fusion']['subjects'] == 1
    assert params['fusion']['skeleton'] == 'human14' and params['fusion']['link_mm'] == 600.0
    # one value for both nodes (their discovery crop slots must agree): fusion.yaml's
    assert params['detector']['discovery_tiles'] == params['fusion']['discovery_tiles'] == 2


def test_two_subjects_reach_the_nodes_and_the_player_waits_for_the_crop_slots(
        repo_root, tmp_path, monkeypatch):
    """`subjects:=2`: detector and fusion track 2 subjects; the fusion node then subscribes
    the crop slots <cam>/crop<k>/heatmaps, k = 0, 1, 2 (docs/subjects.md "Live"), not
    <cam>/heatmaps, so those are what the player waits for (before this, a replay started
    only after wait_for_subscribers_s)."""
    description = launch_description(repo_root, tmp_path, monkeypatch)
    params = node_parameters(description, {'model': 'm.pt', 'bag': 'rec', 'subjects': '2',
                                           'skeleton': 'blobs.yaml', 'link_mm': '450',
                                           'discovery_tiles': '1'})
    assert params['detector']['subjects'] == 2 and params['fusion']['subjects'] == 2
    assert params['detector']['discovery_tiles'] == params['fusion']['discovery_tiles'] == 1
    assert params['fusion']['skeleton'] == 'blobs.yaml' and params['fusion']['link_mm'] == 450.0
    assert params['player']['wait_for_topics'] == [
        '{camera}/crop0/heatmaps', '{camera}/crop1/heatmaps', '{camera}/crop2/heatmaps']
    assert params['player']['bag'] == 'rec'
    # a launch description evaluates once (launch_ros keeps the values): a fresh one
    description = launch_description(repo_root, tmp_path / 'again', monkeypatch)
    with pytest.raises(SubstitutionFailure, match="launch argument subjects: 'two' is not"):
        node_parameters(description, {'model': 'm.pt', 'bag': 'rec', 'subjects': 'two'})
