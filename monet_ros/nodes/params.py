"""ROS parameters mirrored from a typed config dataclass (monet_ros.config).

Every field becomes a declared, read-only parameter with its description, default and
constraints; the values are read back, coerced and validated by constructing the
dataclass, so a bad value is a ConfigError naming the parameter, raised at start.
"""
from dataclasses import MISSING, fields

from rcl_interfaces.msg import ParameterDescriptor, ParameterType

from monet_ros.config import ConfigError, field_kind

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


def descriptor_for(config_cls, f):
    """ParameterDescriptor of one config field (type, description, constraints)."""
    kind, is_tuple = field_kind(config_cls, f.name)
    # dynamic_typing: we coerce ourselves (so `-p threshold_px:=15` is accepted as 15.0) and
    # validate by constructing the dataclass; read-only: values are read once, at start.
    return ParameterDescriptor(
        name=f.name, type=_ROS_TYPES[(kind, is_tuple)],
        description=f.metadata.get('description', ''),
        additional_constraints=_constraints(f.metadata),
        read_only=True, dynamic_typing=True)


def declare_config(node, config_cls, overrides=None):
    """Declare one parameter per field of `config_cls` on `node`, read them back and
    return the validated config instance.

    overrides: optional {name: value} applied on top of the parameters (used when nodes
    are built in-process, e.g. by `monet pipeline`). Raises ConfigError naming the
    parameter (unknown override names included).
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
        default = f.default if f.default is not MISSING else None
        if f.name in overrides:
            default = overrides[f.name]
        if isinstance(default, tuple):
            default = list(default)
        if default == []:
            default = None  # an empty list has no ROS type; NOT_SET reads back as ()
        descriptor = descriptor_for(config_cls, f)
        parameter = node.declare_parameter(f.name, default, descriptor)
        value = parameter.value
        if f.name in overrides:
            value = overrides[f.name]
        values[f.name] = value
    try:
        return config_cls(**values)
    except ConfigError as error:
        raise ConfigError(node.get_name(), error.field, error.message) from None
