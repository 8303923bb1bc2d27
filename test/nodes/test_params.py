"""Config dataclasses mirrored into real ROS parameters (in-process rclpy node)."""
from dataclasses import dataclass
import math

import pytest
import rclpy
from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter

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


# Issue 37: a value inside its declared range whose derived numbers overflow (the fusion
# node's filter_noise_mm 1e200) is refused naming the parameter, at start and live.
HUGE, FLOAT_MAX, TINY = 1e200, 1.7976931348623157e308, 5e-324


def node_configs():
    from monet_ros.nodes import detector, fusion, player
    return [(fusion.FusionNodeConfig, fusion.derive), (detector.DetectorConfig, detector.derive),
            (player.PlayerConfig, player.derive)]


def extremes(config_cls, name):
    """The declared range's ends and huge / tiny finite values of one numeric field."""
    from dataclasses import fields as dc_fields

    from monet_ros.nodes.params import descriptor_for
    f = next(f for f in dc_fields(config_cls) if f.name == name)
    descriptor = descriptor_for(config_cls, f, live=True)
    ends = [v for r in (*descriptor.floating_point_range, *descriptor.integer_range)
            for v in (r.from_value, r.to_value)]
    if isinstance(f.default, float):
        return ends + [HUGE, -HUGE, FLOAT_MAX, TINY, 1e-200]
    return ends + [2 ** 63 - 1, -2 ** 63]


def numeric_fields(config_cls):
    return [name for name, value in vars(config_cls()).items()
            if isinstance(value, (int, float)) and not isinstance(value, bool)]


CASES = [(cls, derive, name, value) for cls, derive in node_configs()
         for name in numeric_fields(cls) for value in extremes(cls, name)]


@pytest.mark.parametrize('config_cls, derive, name, value', CASES,
                         ids=[f'{c.__name__}-{n}-{v!r}' for c, _, n, v in CASES])
def test_every_extreme_value_is_refused_by_name_or_gives_finite_numbers(config_cls, derive,
                                                                         name, value):
    from monet_ros.config import derive_checked
    try:
        config = config_cls(**{name: value})
        derived = derive_checked('node', config, derive)
    except ConfigError as error:
        assert error.field == name, str(error)
        assert str(error).startswith(f"node: parameter '{name}': ") or \
            f"parameter '{name}'" in str(error)
        return
    # accepted: every number it feeds is one a consumer can use (checked here directly)
    for key, item in vars(derived).items():
        if isinstance(item, float):
            assert math.isfinite(item), (key, item)
        elif isinstance(item, int):
            assert -2 ** 63 <= item < 2 ** 63, (key, item)


def test_the_fusion_filter_is_checked_in_the_rig_unit_and_markers_in_metres():
    # the filter settings keep their units (mm, m/s^2) and are checked converted into the
    # rig's: usable in a metre rig, refused naming the parameter in a millimetre one; the
    # camera markers are published in metres (REP 103), so their depth stays in m
    from monet_ros.config import derive_checked
    from monet_ros.nodes.fusion import FusionNodeConfig, derive
    noise = FusionNodeConfig(filter_noise_mm=1e146)
    assert derive_checked('fusion', noise, derive).filter.r2 == pytest.approx(1e286)
    with pytest.raises(ConfigError, match=r"^fusion: parameter 'filter_noise_mm': 1e\+146 mm "
                       'gives a non-finite restart covariance in mm$'):
        derive_checked('fusion', noise, lambda c: derive(c, 'mm'))
    depth = FusionNodeConfig(camera_marker_depth=1e306)
    assert derive_checked('fusion', depth, derive).marker_depth == 1e306
    assert derive_checked('fusion', depth, lambda c: derive(c, 'mm')).marker_depth == 1e306
    # the rig not loaded yet (the node's first check): what depends on its unit left out
    unknown = derive(noise, None)
    assert unknown.filter is None and unknown.marker_depth == 0.2


def test_the_fusion_tracker_is_checked_in_the_rig_unit():
    # the identity tracker (subjects >= 2) squares its noise in the rig's unit: a value
    # usable in a metre rig is refused naming the parameter in a millimetre one, before
    # any subject is tracked (was an OverflowError inside the first frame's tracker)
    from monet_ros.config import derive_checked
    from monet_ros.nodes.fusion import FusionNodeConfig, derive
    noise = FusionNodeConfig(subjects=2, body_noise_mm=1e155)
    tracker = derive_checked('fusion', noise, derive).tracker
    assert tracker._body_r2 == pytest.approx((1e155 / 1e3) ** 2)
    with pytest.raises(ConfigError, match=r"^fusion: parameter 'body_noise_mm': 1e\+155 "
                       'cannot be used: '):
        derive_checked('fusion', noise, lambda c: derive(c, 'mm'))
    assert derive(noise, None).tracker is None


def test_start_and_live_refusals_name_the_parameter(make_node):
    from monet_ros.nodes.fusion import LIVE, FusionNodeConfig, derive
    node = make_node('filter_noise_mm:=1e200')
    with pytest.raises(ConfigError, match=r"^demo: parameter 'filter_noise_mm': 1e\+200 "):
        declare_config(node, FusionNodeConfig, live=LIVE, derive=derive)
    node = make_node()
    applied = []
    config = declare_config(node, FusionNodeConfig, live=LIVE, derive=derive,
                            on_change=applied.append)
    node.config = config
    result = node.set_parameters([Parameter('filter_noise_mm', value=1e200)])[0]
    assert not result.successful and result.reason.startswith("parameter 'filter_noise_mm': ")
    result = node.set_parameters([Parameter('filter_acceleration', value=FLOAT_MAX)])[0]
    assert not result.successful and "'filter_acceleration'" in result.reason
    assert applied == [] and node.get_parameter('filter_noise_mm').value == 20.0
    result = node.set_parameters([Parameter('filter_noise_mm', value=1e5)])[0]
    assert result.successful, result.reason
    assert applied[-1].filter_noise_mm == 1e5


def test_a_failure_while_applying_is_a_refusal_not_the_end_of_the_node(make_node):
    node = make_node()

    def broken(config):
        raise OverflowError('math range error')
    node.config = declare_config(node, Demo, live=('threshold_px',), on_change=broken)
    result = node.set_parameters([Parameter('threshold_px', value=3.0)])[0]
    assert not result.successful
    assert result.reason == ("parameter 'threshold_px': cannot be applied: OverflowError: "
                             'math range error')
