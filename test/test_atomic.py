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


@pytest.mark.parametrize('umask', [0o022, 0o027, 0o077])
def test_files_get_the_mode_open_gives_them(tmp_path, umask):
    """A checkpoint written atomically is as readable as a file open() makes under the same
    umask (before: 0o600 whatever the umask, from tempfile.mkstemp: the detectors of another
    user could not read a checkpoint the learner announced in a shared folder)."""
    import os
    import stat

    import torch

    from monet_ros.models import build_model, save_checkpoint
    previous = os.umask(umask)
    try:
        with open(tmp_path / 'plain.txt', 'w') as stream:        # the independent answer
            stream.write('x')
        with atomic_write(tmp_path / 'state.json', 'w') as stream:
            stream.write('{}')
        model = build_model('small', 3, width=8, input_size=(32, 32))
        save_checkpoint(tmp_path / 'model.pt', model, {'keypoints': ['a', 'b', 'c']})
    finally:
        os.umask(previous)
    expected = stat.S_IMODE((tmp_path / 'plain.txt').stat().st_mode)
    assert expected == 0o666 & ~umask
    for name in ('state.json', 'model.pt'):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == expected, name
    assert torch.load(tmp_path / 'model.pt', weights_only=True)
