"""The project's errors with their own fields survive a process boundary: raised in a
worker (`monet process` over several recordings, the benches' process pools), they reach
the parent as the same error, not as a broken pool (the default unpickling calls the class
with the message alone: TypeError)."""
from concurrent.futures import ProcessPoolExecutor
import pickle

import pytest

from monet_ros.calibration.board import BoardError
from monet_ros.config import ConfigError
from monet_ros.geometry.camera import CameraError
from monet_ros.geometry.rig_fields import RigError
from monet_ros.models.registry import OptionError

ERRORS = [
    (ConfigError, ('TrainConfig', 'precision', 'needs AVX512-BF16'), 'field'),
    (CameraError, ('cam1', 'K', 'not numeric'), 'field'),
    (RigError, ('/x/rig.yaml', 'width', 'must be an integer'), 'field'),
    (OptionError, ('width', 'must be in 1..1024'), 'option'),
    (BoardError, ('squares', 'must be 2 numbers', '/x/board.toml'), 'path'),
]


def _raise(cls, args):
    raise cls(*args)


@pytest.mark.parametrize('cls, args, attribute', ERRORS, ids=[e[0].__name__ for e in ERRORS])
def test_an_error_pickles_as_itself(cls, args, attribute):
    error = cls(*args)
    back = pickle.loads(pickle.dumps(error))
    assert type(back) is cls and str(back) == str(error)
    assert getattr(back, attribute) == getattr(error, attribute)


@pytest.mark.parametrize('cls, args, attribute', ERRORS[:1] + ERRORS[2:3],
                         ids=['ConfigError', 'RigError'])
def test_an_error_raised_in_a_worker_process_reaches_the_parent(cls, args, attribute):
    with ProcessPoolExecutor(1) as pool:
        with pytest.raises(cls) as caught:
            pool.submit(_raise, cls, args).result()
    assert str(caught.value) == str(cls(*args))
