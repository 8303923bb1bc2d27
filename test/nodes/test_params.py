"""Config dataclasses mirrored into real ROS parameters (in-process rclpy node)."""
from dataclasses import dataclass

import pytest
import rclpy
from rclpy.context import Context
from rclpy.node import Node

from monet_ros.config import ConfigError, setting, validate_config
from monet_ros.nodes.params import declare_config


@dataclass(frozen=True)
class Demo:
    rig: str = setting('', 'rig file')
    cameras: tuple[str, ...] = setting((), 'camera names (default: all)')
    threshold_px: float = setting(15.0, 'inlier threshold (px)', minimum=0.0)
    min_views: int = setting(2, 'fewest views', minimum=2)
    box: tuple[float, ...] = setting((), 'crop box', length=(0, 4))
    overlay: bool = setting(False, 'publish overlays')

    def __post_init__(self):
        validate_config(self)


@pytest.fixture
def make_node(ros_env):
    context = Context()
    rclpy.init(context=context, domain_id=int(ros_env['ROS_DOMAIN_ID']))
    nodes = []

    def make(*params):
        cli = ['--ros-args'] + [arg for p in params for arg in ('-p', p)]
        node = Node('demo', context=context, cli_args=cli)
        nodes.append(node)
        return node

    yield make
    for node in nodes:
        node.destroy_node()
    rclpy.try_shutdown(context=context)


def test_declares_typed_described_parameters(make_node):
    node = make_node()
    config = declare_config(node, Demo)
    assert config == Demo()
    descriptor = node.describe_parameter('threshold_px')
    assert descriptor.description == 'inlier threshold (px)'
    assert descriptor.additional_constraints == '>= 0.0'
    assert descriptor.read_only
    assert node.get_parameter('threshold_px').value == 15.0
    assert node.get_parameter('min_views').value == 2


def test_command_line_values_are_coerced(make_node):
    node = make_node('threshold_px:=4', 'cameras:=[cam1, cam3]', 'box:=[0, 0, 640, 480]',
                     'overlay:=true', 'rig:=/tmp/rig.yaml')
    config = declare_config(node, Demo)
    assert config.threshold_px == 4.0 and config.cameras == ('cam1', 'cam3')
    assert config.box == (0.0, 0.0, 640.0, 480.0) and config.overlay is True
    assert config.rig == '/tmp/rig.yaml'


def test_overrides_in_process(make_node):
    config = declare_config(make_node(), Demo, overrides={'cameras': ('a', 'b'), 'min_views': 3})
    assert config.cameras == ('a', 'b') and config.min_views == 3
    with pytest.raises(ConfigError, match="'min_view': unknown parameter"):
        declare_config(make_node(), Demo, overrides={'min_view': 3})


@pytest.mark.parametrize('arg, text', [
    ('min_views:=1', "demo: parameter 'min_views': must be >= 2, got 1"),
    ('threshold_px:=abc', "demo: parameter 'threshold_px': expected float, got 'abc'"),
    ('box:=[1.0, 2.0]', "demo: parameter 'box': expected 0 or 4 values"),
])
def test_bad_value_is_a_clear_error(make_node, arg, text):
    with pytest.raises(ConfigError) as info:
        declare_config(make_node(arg), Demo)
    assert text in str(info.value)
