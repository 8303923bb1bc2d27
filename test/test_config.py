"""Typed config dataclasses: coercion and validation errors that name the field."""
from dataclasses import dataclass, replace
import math

import numpy as np
import pytest

from monet_ros.config import (
    ConfigError,
    config_from_mapping,
    config_subset,
    derive_checked,
    setting,
    validate_config,
)


@dataclass(frozen=True)
class Core:
    threshold_px: float = setting(15.0, 'inlier threshold', minimum=0.0, exclusive_minimum=True)
    method: str = setting('exclusion', 'method', choices=('exclusion', 'ransac'))

    def __post_init__(self):
        validate_config(self)


@dataclass(frozen=True)
class Full(Core):
    cameras: tuple[str, ...] = setting((), 'camera names')
    box: tuple[float, ...] = setting((), 'crop box', length=(0, 4))
    min_views: int = setting(2, 'views', minimum=2)
    overlay: bool = setting(False, 'overlay')


def test_defaults_and_coercion():
    config = Full(threshold_px=3, cameras=['a', 'b'], box=[0, 0, 10, 20])
    assert config.threshold_px == 3.0 and isinstance(config.threshold_px, float)
    assert config.cameras == ('a', 'b')
    assert config.box == (0.0, 0.0, 10.0, 20.0)
    assert config_subset(config, Core) == Core(threshold_px=3.0)


@pytest.mark.parametrize('changes, field, text', [
    ({'threshold_px': 0.0}, 'threshold_px', 'must be > 0.0'),
    ({'threshold_px': float('nan')}, 'threshold_px', 'finite'),
    ({'method': 'median'}, 'method', "'median' is not one of"),
    ({'min_views': 1}, 'min_views', 'must be >= 2'),
    ({'min_views': 2.5}, 'min_views', 'expected int'),
    ({'overlay': 1}, 'overlay', 'expected bool'),
    ({'box': [1, 2, 3]}, 'box', 'expected 0 or 4 values'),
    ({'cameras': 'cam0'}, 'cameras', 'expected a list of str'),
])
def test_bad_values_name_the_field(changes, field, text):
    with pytest.raises(ConfigError) as info:
        Full(**changes)
    assert info.value.field == field
    assert field in str(info.value) and text in str(info.value)


def test_unknown_key_in_mapping():
    with pytest.raises(ConfigError, match="'treshold_px': unknown parameter in f.yaml"):
        config_from_mapping(Full, {'treshold_px': 1.0}, source='f.yaml')


@dataclass(frozen=True)
class Timing:
    period_s: float = setting(1.5, 'a timer period', minimum=0.0, exclusive_minimum=True)
    steps: float = setting(10.0, 'steps of the period', minimum=0.0)
    gain: float = setting(2.0, 'gain', minimum=0.0)

    def __post_init__(self):
        validate_config(self)


def timing_numbers(config):
    """What Timing feeds: a period in int ns, the span of all steps (s), a squared gain."""
    if config.gain > 1e6:
        raise ConfigError('Timing', 'gain', 'must be <= 1e6 for what it feeds')
    return {'period_ns': int(config.period_s * 1e9), 'span_s': config.period_s * config.steps,
            'gain2': np.float64(config.gain) ** 2}


@pytest.mark.parametrize('changes, field, text', [
    (dict(period_s=1e200), 'period_s', 'period_ns = 1e+209 (beyond int64)'),
    (dict(period_s=1.7976931348623157e308), 'period_s', 'OverflowError: cannot convert float'),
    (dict(steps=1.7976931348623157e308), 'steps', 'span_s = inf'),
    (dict(gain=1e7), 'gain', 'must be <= 1e6 for what it feeds'),   # derive's own error
])
def test_derived_numbers_that_overflow_name_the_parameter(changes, field, text):
    config = Timing(**changes)        # inside the declared ranges
    with pytest.raises(ConfigError) as info:
        derive_checked('node', config, timing_numbers)
    assert info.value.field == field and text in str(info.value), str(info.value)
    assert str(info.value).startswith(f"node: parameter '{field}': ")


def test_derived_numbers_blame_the_changed_parameter_of_a_product():
    # period 1e300 s x 10 steps is fine, x 1e10 steps overflows: a change of steps from a
    # config with that period names steps; a change of the period from many steps, period
    big = Timing(period_s=1e8, steps=1e300)
    assert math.isfinite(derive_checked('n', big, timing_numbers)['span_s'])
    with pytest.raises(ConfigError) as info:
        derive_checked('n', replace(big, steps=1.7e308), timing_numbers, base=big,
                       blame=['steps'])
    assert info.value.field == 'steps'
    many = Timing(steps=1e308)
    with pytest.raises(ConfigError) as info:
        derive_checked('n', replace(many, period_s=1e3), timing_numbers, base=many)
    assert info.value.field == 'period_s'


def test_usable_derived_numbers_are_returned():
    derived = derive_checked('n', Timing(period_s=2.5, gain=3.0), timing_numbers)
    assert derived == {'period_ns': 2_500_000_000, 'span_s': 25.0, 'gain2': 9.0}
