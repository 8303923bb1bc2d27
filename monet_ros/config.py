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
from dataclasses import field, fields, is_dataclass, replace
import math
import string
import typing

import numpy as np

SCALAR_TYPES = (str, int, float, bool)
# Most CPU threads a `threads` setting may ask for (torch refuses more than int32 with a bare
# "Overflow when unpacking long"; far fewer already exhaust a machine).
MAX_THREADS = 1024


class ConfigError(ValueError):
    """A configuration value is invalid; `.field` names it (and `.owner` the config)."""

    def __init__(self, owner, field_name, message):
        self.owner = owner
        self.field = field_name
        self.message = message
        super().__init__(f'{owner}: parameter {field_name!r}: {message}')

    def __reduce__(self):
        # raised in a worker process (monet process over several recordings, benches): it
        # must unpickle in the parent, which calls the class with these arguments (the
        # default would call it with the message alone)
        return type(self), (self.owner, self.field, self.message)


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


INT64_MAX = 2 ** 63 - 1
_WALK_DEPTH = 4


def non_finite(value, path='', depth=0):
    """The first number in `value` a consumer cannot use, as 'path = value', or None.

    Walks dicts, lists, tuples, dataclasses and plain objects' attributes (a few levels):
    a float or numpy float array must be finite, an int must fit int64 (durations in ns go
    to rcl and to numpy as int64)."""
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return None
    if isinstance(value, (int, np.integer)):
        return None if -INT64_MAX - 1 <= int(value) <= INT64_MAX else \
            f'{path or "value"} = {float(value):.3g} (beyond int64)'
    if isinstance(value, (float, np.floating)):
        return None if math.isfinite(value) else f'{path or "value"} = {float(value)!r}'
    if isinstance(value, np.ndarray):
        if value.dtype.kind in 'fc' and not np.isfinite(value).all():
            return f'{path or "value"} has non-finite entries'
        return None
    if depth >= _WALK_DEPTH:
        return None
    if isinstance(value, dict):
        items = value.items()
    elif isinstance(value, (list, tuple)):
        items = enumerate(value)
    elif is_dataclass(value):
        items = ((f.name, getattr(value, f.name)) for f in fields(value))
    elif hasattr(value, '__dict__') and not isinstance(value, type):
        items = vars(value).items()
    else:
        return None
    for key, item in items:
        found = non_finite(item, f'{path}.{key}' if path else str(key), depth + 1)
        if found:
            return found
    return None


def _derive_problem(derive, config):
    """(None, derived) when derive(config) succeeds with usable numbers, else
    (ConfigError or reason text, None)."""
    try:
        with np.errstate(all='ignore'):
            derived = derive(config)
    except ConfigError as error:
        return error, None
    except (ArithmeticError, ValueError, TypeError, RuntimeError, MemoryError) as error:
        text = ' '.join(str(error).split()) or type(error).__name__
        return f'{type(error).__name__}: {text}', None
    found = non_finite(derived)
    if found:
        return f'it gives {found}', None
    return None, derived


def derive_checked(owner, config, derive, base=None, blame=None):
    """derive(config) -> what the settings feed (filter matrices, durations in ns, ...),
    refused unless it can be used: ConfigError naming a parameter when derive raises or its
    result holds a non-finite float or an int beyond int64 (see non_finite).

    owner: the node or command named in the error. base: the config the change is made
    from (default: the dataclass's defaults); the fields that differ from it are the
    suspects, and the first one that fails on its own (set on `base`) is named, else all
    are. blame: names to try first (e.g. the parameters just set). A ConfigError raised
    by derive keeps its field. Returns the derived value."""
    problem, derived = _derive_problem(derive, config)
    if problem is None:
        return derived
    if isinstance(problem, ConfigError):
        raise ConfigError(owner, problem.field, problem.message) from None
    base = type(config)() if base is None else base
    names = [f.name for f in fields(config) if f.init]
    suspects = [n for n in names if getattr(config, n) != getattr(base, n)]
    order = [n for n in (blame or ()) if n in suspects] + \
        [n for n in suspects if n not in (blame or ())]
    for name in order:
        try:
            alone = replace(base, **{name: getattr(config, name)})
        except ConfigError:
            continue
        if _derive_problem(derive, alone)[0] is not None:
            raise ConfigError(owner, name, f'{getattr(config, name)!r} cannot be used: '
                              f'{problem}') from None
    named = order[0] if order else 'unknown'
    others = ', '.join(order[1:])
    raise ConfigError(owner, named, f'{getattr(config, named, None)!r} cannot be used'
                      f'{" together with " + others if others else ""}: {problem}') from None


__all__ = ['MAX_THREADS', 'check_template', 'ConfigError', 'coerce_value', 'config_from_mapping',
           'config_subset', 'derive_checked', 'field_kind', 'non_finite', 'setting',
           'validate_config']
