"""Typed, frozen, validated configuration dataclasses (no ROS).

A config is a frozen dataclass whose fields are declared with `setting(...)`; the
metadata (description, choices, range) drives validation on construction and the
ROS parameter declarations of the nodes (monet_ros/nodes/params.py)::

    @dataclass(frozen=True)
    class FusionConfig:
        threshold_px: float = setting(15.0, 'reprojection error (px) of an inlier view',
                                      minimum=0.0, exclusive_minimum=True)

        def __post_init__(self):
            validate_config(self)

Supported field types: str, int, float, bool and tuple[str | int | float, ...].
"""
from dataclasses import field, fields
import math
import string
import typing

SCALAR_TYPES = (str, int, float, bool)


class ConfigError(ValueError):
    """A configuration value is invalid; `.field` names it (and `.owner` the config)."""

    def __init__(self, owner, field_name, message):
        self.owner = owner
        self.field = field_name
        self.message = message
        super().__init__(f'{owner}: parameter {field_name!r}: {message}')


def setting(default, description, *, choices=None, minimum=None, maximum=None,
            exclusive_minimum=False, min_length=None, length=None, template_fields=None):
    """A dataclass field with a default and the metadata `validate_config` checks.

    choices: allowed values (for tuples: allowed elements); minimum/maximum: numeric bounds
    (inclusive unless exclusive_minimum; for tuples: per element); min_length / length: tuple
    length constraints (length may be a tuple of allowed lengths); template_fields: the
    str.format fields a template string may use (e.g. ('camera',) for '/{camera}/image').
    """
    if isinstance(default, list):
        default = tuple(default)
    meta = {'description': description, 'choices': tuple(choices) if choices else None,
            'minimum': minimum, 'maximum': maximum, 'exclusive_minimum': exclusive_minimum,
            'min_length': min_length, 'length': length,
            'template_fields': tuple(template_fields) if template_fields else None}
    return field(default=default, metadata=meta)


def field_kind(config_cls, name):
    """(base type, is_tuple) of a config field from its annotation, e.g. (float, True)."""
    hint = typing.get_type_hints(config_cls)[name]
    if hint in SCALAR_TYPES:
        return hint, False
    if typing.get_origin(hint) is tuple:
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is Ellipsis and args[0] in SCALAR_TYPES:
            return args[0], True
    raise TypeError(f'{config_cls.__name__}.{name}: unsupported config type {hint!r}')


def coerce_value(owner, name, kind, is_tuple, value):
    """Convert `value` to the field's type or raise ConfigError naming the field.

    int is accepted for float; lists for tuples; a float with an integral value for int.
    """
    def one(item):
        if kind is bool:
            if isinstance(item, bool):
                return item
        elif kind is int:
            if isinstance(item, int) and not isinstance(item, bool):
                return item
            if isinstance(item, float) and item.is_integer():
                return int(item)
        elif kind is float:
            if isinstance(item, (int, float)) and not isinstance(item, bool):
                return float(item)
        elif isinstance(item, str):
            return item
        raise ConfigError(owner, name, f'expected {kind.__name__}'
                          f'{" elements" if is_tuple else ""}, got {item!r}')

    if is_tuple:
        if value is None:
            return ()
        if isinstance(value, (str, bytes)) or not hasattr(value, '__iter__'):
            raise ConfigError(owner, name, f'expected a list of {kind.__name__}, got {value!r}')
        return tuple(one(item) for item in value)
    return one(value)


def validate_config(config):
    """Check every field of a config dataclass instance against its type and metadata.

    Coerces in place (int -> float, list -> tuple) and raises ConfigError on a bad value.
    """
    owner = type(config).__name__
    for f in fields(config):
        if not f.init:
            continue
        kind, is_tuple = field_kind(type(config), f.name)
        value = coerce_value(owner, f.name, kind, is_tuple, getattr(config, f.name))
        object.__setattr__(config, f.name, value)
        meta = f.metadata
        items = value if is_tuple else (value,)
        if is_tuple:
            lengths = meta.get('length')
            if lengths is not None:
                lengths = (lengths,) if isinstance(lengths, int) else tuple(lengths)
                if len(value) not in lengths:
                    raise ConfigError(owner, f.name, f'expected {" or ".join(map(str, lengths))}'
                                      f' values, got {len(value)}: {list(value)}')
            if meta.get('min_length') is not None and len(value) < meta['min_length']:
                raise ConfigError(owner, f.name, f'expected at least {meta["min_length"]} '
                                  f'values, got {len(value)}: {list(value)}')
        for item in items:
            if meta.get('template_fields') is not None and isinstance(item, str):
                check_template(owner, f.name, item, meta['template_fields'])
            if meta.get('choices') and item not in meta['choices']:
                raise ConfigError(owner, f.name, f'{item!r} is not one of '
                                  f'{list(meta["choices"])}')
            if kind in (int, float):
                if isinstance(item, float) and not math.isfinite(item):
                    raise ConfigError(owner, f.name, f'must be finite, got {item!r}')
                low, high = meta.get('minimum'), meta.get('maximum')
                if low is not None:
                    if meta.get('exclusive_minimum') and not item > low:
                        raise ConfigError(owner, f.name, f'must be > {low}, got {item!r}')
                    if item < low:
                        raise ConfigError(owner, f.name, f'must be >= {low}, got {item!r}')
                if high is not None and item > high:
                    raise ConfigError(owner, f.name, f'must be <= {high}, got {item!r}')
    return config


def check_template(owner, name, text, allowed):
    """ConfigError unless `text` is a str.format template using only the `allowed` fields
    (plain names, no conversions or format specs)."""
    try:
        parsed = list(string.Formatter().parse(text))
    except ValueError as error:
        raise ConfigError(owner, name, f'{text!r}: not a valid template ({error})') from None
    for _, field_name, spec, conversion in parsed:
        if field_name is None:
            continue
        if field_name not in allowed or spec or conversion:
            raise ConfigError(owner, name, f'{text!r}: unknown template field '
                              f'{{{field_name}}}; allowed: '
                              f'{", ".join("{" + a + "}" for a in allowed)}')


def config_subset(config, target_cls):
    """An instance of `target_cls` built from the same-named fields of `config`
    (e.g. the core FusionConfig out of the node's FusionNodeConfig)."""
    names = {f.name for f in fields(target_cls) if f.init}
    return target_cls(**{name: getattr(config, name) for name in names})


def config_from_mapping(config_cls, values, source='<mapping>'):
    """Build a config from a mapping (e.g. YAML), rejecting unknown keys by name."""
    known = {f.name for f in fields(config_cls) if f.init}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ConfigError(config_cls.__name__, unknown[0],
                          f'unknown parameter in {source} (known: {sorted(known)})')
    return config_cls(**values)


__all__ = ['check_template', 'ConfigError', 'coerce_value', 'config_from_mapping',
           'config_subset', 'field_kind', 'setting', 'validate_config']
