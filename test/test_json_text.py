"""json_text: what the commands write is valid JSON, a non-finite number written as null."""
import json
import math

import numpy as np
import pytest

from monet_ros.json_text import dumps, finite_or_none


def test_non_finite_numbers_are_null_at_any_depth():
    value = {'px_median': math.inf, 'mean': float('nan'), 'ok': 1.5, 'n': np.int64(3),
             'rows': [{'mm': np.float32('nan'), 'x': np.float64(2.0)}, (math.inf, -math.inf)],
             'array': np.array([1.0, np.nan]), 'name': 'a', 'flag': True, 'none': None}
    text = dumps(value, indent=1)

    def refuse(token):
        raise ValueError(token)
    assert json.loads(text, parse_constant=refuse) == {
        'px_median': None, 'mean': None, 'ok': 1.5, 'n': 3,
        'rows': [{'mm': None, 'x': 2.0}, [None, None]], 'array': [1.0, None], 'name': 'a',
        'flag': True, 'none': None}
    assert 'Infinity' not in text and 'NaN' not in text
    assert finite_or_none(math.nan) is None and finite_or_none(2) == 2


def test_what_json_cannot_write_is_still_an_error():
    with pytest.raises(TypeError):
        dumps({'x': object()})
