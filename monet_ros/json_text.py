"""Valid JSON for what the commands write (summaries on stdout, reference.json, results.json,
the learner's announcements): a non-finite number (NaN, inf: a median of misses, an empty
mean) is written as null, never as Python's NaN / Infinity tokens, which are not JSON and
which strict parsers reject."""
import json
import math

import numpy as np


def finite_or_none(value):
    """`value` with every non-finite float (Python or numpy, in dicts, lists and tuples, at
    any depth) replaced by None; numpy scalars as Python numbers, numpy arrays as lists.
    Other values are returned as they are."""
    if isinstance(value, dict):
        return {k: finite_or_none(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_or_none(v) for v in value]
    if isinstance(value, np.ndarray):
        return finite_or_none(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def dumps(value, **kwargs):
    """json.dumps of finite_or_none(value) (keyword arguments as json.dumps'): valid JSON,
    non-finite numbers as null; TypeError, as json.dumps, for a value it cannot write."""
    return json.dumps(finite_or_none(value), allow_nan=False, **kwargs)
