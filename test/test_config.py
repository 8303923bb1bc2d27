"""Typed config dataclasses: coercion and validation errors that name the field."""
from dataclasses import dataclass

import pytest

from monet_ros.config import (
    ConfigError,
    config_from_mapping,
    config_subset,
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
