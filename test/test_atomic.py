"""atomic_write: the target is replaced whole or not at all, and no temporary file is left."""
import pytest

from monet_ros.atomic import atomic_write


def test_success_replaces_the_file_whole(tmp_path):
    target = tmp_path / 'sub' / 'state.json'
    with atomic_write(target, 'w') as stream:
        stream.write('new')
    assert target.read_text() == 'new'
    assert [p.name for p in target.parent.iterdir()] == ['state.json']


def test_failure_mid_write_keeps_the_old_file_and_removes_the_temporary(tmp_path):
    target = tmp_path / 'model.pt'
    target.write_bytes(b'old weights')
    with pytest.raises(RuntimeError, match='disk full'):
        with atomic_write(target) as stream:
            stream.write(b'half of the new wei')
            raise RuntimeError('disk full')
    assert target.read_bytes() == b'old weights'
    assert [p.name for p in tmp_path.iterdir()] == ['model.pt']
