"""ROS parameters mirrored from a typed config dataclass (monet_ros.config).

Every field becomes a declared parameter with its description, default, constraints (as
text and as a structured floating_point_range / integer_range) and is read back, coerced
and validated by constructing the dataclass, so a bad value is a ConfigError naming the
parameter, raised at start. A value inside its declared range can still be unusable for what
it feeds (filter_noise_mm 1e200: its square overflows; a duration in s beyond int64 ns): the
node's `derive(config)` computes that (the filter's numbers, durations in ns, ...) and the
value is refused unless it succeeds with finite numbers (monet_ros.config.derive_checked),
at start and at every live change alike. Fields named in `live` stay settable at run time
(`ros2 param set`, rcl_interfaces/srv/SetParameters): a change is validated through the same
dataclass and derive (plus the node's own check) and takes effect on the next frame; a refused
change says which parameter and why, and the node goes on with its old values. Every other
parameter is read-only. An empty list has no ROS type: it is declared unset (`ros2 param
dump` writes `null`), and `null`, `~`, '' and `[]` all load back as an empty list.
"""
from dataclasses import MISSING, fields, replace
import math
import sys

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from rclpy.exceptions import InvalidParameterValueException

from monet_ros.config import ConfigError, derive_checked, field_kind
from monet_ros.error_text import error_line

_ROS_TYPES = {
    (str, False): ParameterType.PARAMETER_STRING,
    (int, False): ParameterType.PARAMETER_INTEGER,
    (float, False): ParameterType.PARAMETER_DOUBLE,
    (bool, False): ParameterType.PARAMETER_BOOL,
    (str, True): ParameterType.PARAMETER_STRING_ARRAY,
    (int, True): ParameterType.PARAMETER_INTEGER_ARRAY,
    (float, True): ParameterType.PARAMETER_DOUBLE_ARRAY,
    (bool, True): ParameterType.PARAMETER_BOOL_ARRAY,
}
# What a YAML file or a dump may hold for an empty list.
_EMPTY_SPELLINGS = ('', 'null', '~', '[]', 'None')
_INT_MAX = 2 ** 63 - 1


def _constraints(meta):
    """Human-readable constraint text for the parameter descriptor."""
    parts = []
    if meta.get('choices'):
        parts.append(f'one of {list(meta["choices"])}')
    if meta.get('minimum') is not None:
        parts.append(('> ' if meta.get('exclusive_minimum') else '>= ') + str(meta['minimum']))
    if meta.get('maximum') is not None:
        parts.append(f'<= {meta["maximum"]}')
    if meta.get('length') is not None:
        parts.append(f'length {meta["length"]}')
    if meta.get('min_length') is not None:
        parts.append(f'at least {meta["min_length"]} values')
    return ', '.join(parts)


def _ranges(kind, is_tuple, meta):
    """(floating_point_range, integer_range) lists of a scalar numeric field's bounds."""
    low, high = meta.get('minimum'), meta.get('maximum')
    if is_tuple or (low is None and high is None):
        return [], []
    if kind is float:
        low = -sys.float_info.max if low is None else float(low)
        if meta.get('exclusive_minimum'):
            low = math.nextafter(low, math.inf)
        high = sys.float_info.max if high is None else float(high)
        return [FloatingPointRange(from_value=low, to_value=high, step=0.0)], []
    if kind is int:
        low = -_INT_MAX - 1 if low is None else int(low) + bool(meta.get('exclusive_minimum'))
        high = _INT_MAX if high is None else int(high)
        return [], [IntegerRange(from_value=low, to_value=high, step=0)]
    return [], []


def descriptor_for(config_cls, f, live=False):
    """ParameterDescriptor of one config field (type, description, constraints, ranges)."""
    kind, is_tuple = field_kind(config_cls, f.name)
    floating, integer = _ranges(kind, is_tuple, f.metadata)
    description = f.metadata.get('description', '')
    if live:
        description += ' (settable at run time, effective next frame)'
    # dynamic_typing: we coerce ourselves (so `-p threshold_px:=15` is accepted as 15.0) and
    # validate by constructing the dataclass.
    return ParameterDescriptor(
        name=f.name, type=_ROS_TYPES[(kind, is_tuple)], description=description,
        additional_constraints=_constraints(f.metadata),
        floating_point_range=floating, integer_range=integer,
        read_only=not live, dynamic_typing=True)


def parameter_value(config_cls, name, value):
    """A parameter value as the config field expects it: an empty-list spelling -> ()."""
    _, is_tuple = field_kind(config_cls, name)
    if is_tuple and (value is None or (isinstance(value, str)
                                       and value.strip() in _EMPTY_SPELLINGS)):
        return ()
    return value


def declare_config(node, config_cls, overrides=None, live=(), on_change=None, derive=None):
    """Declare one parameter per field of `config_cls` on `node`, read them back and
    return the validated config instance.

    overrides: optional {name: value} applied on top of the parameters (used when nodes
    are built in-process, e.g. by `monet pipeline`). live: names that may change at run
    time; on each accepted change `on_change(new_config)` is called (it may raise
    ConfigError to refuse it) and must make the node use the new config, changing nothing
    when it raises. derive: config -> what the parameters feed, checked at start and before
    each change (derive_checked). Raises ConfigError naming the parameter (unknown override
    names included).
    """
    overrides = dict(overrides or {})
    names = [f.name for f in fields(config_cls) if f.init]
    unknown = sorted(set(overrides) - set(names))
    if unknown:
        raise ConfigError(node.get_name(), unknown[0], f'unknown parameter (known: {names})')
    values = {}
    for f in fields(config_cls):
        if not f.init:
            continue
        kind, is_tuple = field_kind(config_cls, f.name)
        default = f.default if f.default is not MISSING else None
        if f.name in overrides:
            default = overrides[f.name]
        if isinstance(default, tuple):
            default = list(default)
        if is_tuple and not default:
            default = None   # an empty list has no ROS type: NOT_SET (dumps as null)
        descriptor = descriptor_for(config_cls, f, live=f.name in live)
        try:
            parameter = node.declare_parameter(f.name, default, descriptor)
        except InvalidParameterValueException:
            # out of the declared range: declare it unchecked, the config names the problem
            descriptor.floating_point_range, descriptor.integer_range = [], []
            parameter = node.declare_parameter(f.name, default, descriptor)
        value = parameter.value
        if f.name in overrides:
            value = overrides[f.name]
        values[f.name] = parameter_value(config_cls, f.name, value)
    try:
        config = config_cls(**values)
    except ConfigError as error:
        raise ConfigError(node.get_name(), error.field, error.message) from None
    if derive is not None:
        derive_checked(node.get_name(), config, derive)
    if live:
        node.add_on_set_parameters_callback(
            lambda params: _set_live(node, config_cls, live, on_change, params, derive))
    return config


def duration_msg_ns(seconds):
    """A duration in s as int ns that a builtin_interfaces/Duration (int32 seconds) holds.
    Raises OverflowError (inf) or ValueError (beyond int32 seconds)."""
    ns = int(seconds * 1e9)
    if not 0 <= ns // 1_000_000_000 < 2 ** 31:
        raise ValueError(f'{seconds!r} s does not fit a Duration message (int32 seconds)')
    return ns


def _set_live(node, config_cls, live, on_change, params, derive=None):
    """on_set_parameters callback: validate the change through the config and what it
    feeds (derive), then apply. Any failure refuses the change with its reason (naming the
    parameter); nothing raised here may reach rclpy, which would end the node."""
    changes = {}
    for param in params:
        if param.name not in live:
            return SetParametersResult(successful=False,
                                       reason=f'parameter {param.name!r} is read-only')
        changes[param.name] = parameter_value(config_cls, param.name, param.value)
    try:
        new = replace(node.config, **changes)
        if derive is not None:
            derive_checked(node.get_name(), new, derive, base=node.config, blame=changes)
        if on_change is not None:
            on_change(new)
    except ConfigError as error:
        named = '' if error.field in changes else \
            f'parameter {", ".join(map(repr, changes))}: '
        return SetParametersResult(successful=False,
                                   reason=f'{named}parameter {error.field!r}: {error.message}')
    except Exception as error:  # noqa: BLE001 - refused, never the end of the node
        return SetParametersResult(
            successful=False, reason=f'parameter {", ".join(map(repr, changes))}: '
            f'cannot be applied: {type(error).__name__}: {error_line(error)}')
    return SetParametersResult(successful=True)
