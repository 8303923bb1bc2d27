"""Atomic file writes: a crash or kill mid-write never leaves a partial file behind.

Checkpoints, trainer state and announcements all go through `atomic_write`: the payload
goes to a temporary file in the same folder, is fsynced, then renamed over the target
(os.replace is atomic on POSIX); the folder is fsynced so the rename survives a crash.
"""
from contextlib import contextmanager
import hashlib
import os
from pathlib import Path
import tempfile


@contextmanager
def atomic_write(path, mode='wb'):
    """Context manager yielding a stream; on success the file appears at `path` whole, on any
    exception (or KeyboardInterrupt) the temporary file is removed and `path` is untouched."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f'.{path.name}.', suffix='.tmp', dir=path.parent)
    try:
        with os.fdopen(fd, mode) as stream:
            yield stream
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    try:  # make the rename durable (best effort; not every platform can fsync a folder)
        dir_fd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dir_fd)
        finally:
            os.close(dir_fd)
    except OSError:
        pass


def sha256_file(path):
    """Hex sha256 of a file's bytes (read in 1 MiB blocks)."""
    digest = hashlib.sha256()
    with open(path, 'rb') as stream:
        for block in iter(lambda: stream.read(1 << 20), b''):
            digest.update(block)
    return digest.hexdigest()
