"""config/<node>.yaml: every parameter of the node's config, a comment on each, and values
that rcl parses and the config dataclass accepts."""
from dataclasses import fields
import importlib

import pytest
import rclpy
from rclpy.context import Context
from rclpy.node import Node
import yaml

from monet_ros.nodes.params import declare_config

NODES = {'fusion': ('monet_ros.nodes.fusion', 'FusionNodeConfig'),
         'player': ('monet_ros.nodes.player', 'PlayerConfig'),
         'detector': ('monet_ros.nodes.detector', 'DetectorConfig'),
         'learner': ('monet_ros.learning.online', 'LearnerConfig')}


@pytest.mark.parametrize('name', sorted(NODES))
def test_config_file_declares_and_documents_every_parameter(name, repo_root, ros_env):
    module, cls_name = NODES[name]
    config_cls = getattr(importlib.import_module(module), cls_name)
    path = repo_root / 'config' / f'{name}.yaml'
    # '/**/<node>': the node in any namespace (the default is /monet)
    params = yaml.safe_load(path.read_text())[f'/**/{name}']['ros__parameters']
    assert set(params) == {f.name for f in fields(config_cls) if f.init}
    lines = path.read_text().splitlines()
    for key in params:
        index = next(i for i, line in enumerate(lines) if line.strip().startswith(f'{key}:'))
        assert lines[index - 1].strip().startswith('#'), f'{name}.yaml: {key} has no comment'
    context = Context()
    rclpy.init(context=context, domain_id=int(ros_env['ROS_DOMAIN_ID']))
    try:
        node = Node(name, namespace='monet', context=context,
                    cli_args=['--ros-args', '--params-file', str(path)])
        config = declare_config(node, config_cls)
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    assert config == config_cls(**params)


# The settings a config file sets on purpose to something other than the code's default
# (each said in its comment): the learner's required inputs (example values) and its share
# of a machine that also runs the live nodes.
NOT_DEFAULT = {'learner': {'bags', 'out', 'threads', 'views_per_instant'}}


@pytest.mark.parametrize('name', sorted(NODES))
def test_config_file_values_are_the_defaults(name, repo_root):
    # a file that silently differs from the code (fusion.yaml said rival_peaks: false
    # after the default became true) gives `--params-file` users another node than the
    # documented one
    module, cls_name = NODES[name]
    config_cls = getattr(importlib.import_module(module), cls_name)
    params = yaml.safe_load((repo_root / 'config' / f'{name}.yaml').read_text())[
        f'/**/{name}']['ros__parameters']
    defaults = {f.name: list(f.default) if isinstance(f.default, tuple) else f.default
                for f in fields(config_cls) if f.init}
    differ = {k: (v, defaults[k]) for k, v in params.items() if v != defaults[k]}
    assert set(differ) == NOT_DEFAULT.get(name, set()), differ
