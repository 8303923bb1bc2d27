"""Atomic file writes: a crash or kill mid-write never leaves a partial file behind.

Checkpoints, trainer state and announcements all go through `atomic_write`: the payload
goes to a temporary file in the same folder, is fsynced, then renamed over the target
(os.replace is atomic on POSIX); the folder is fsynced so the rename survives a crash.
"""
from contextlib import contextmanager
import errno
import hashlib
import os
from pathlib import Path
import secrets
import shutil

# Free bytes below which a failed write is reported as a full disk (torch's zip writer
# raises RuntimeError "enforce fail at inline_container.cc", without errno or path).
_NEARLY_FULL = 1 << 20


class DiskFullError(OSError):
    """A write failed because the file system is full; names the file."""


def _disk_full(error, folder):
    """True when `error` (raised while writing into `folder`) means: no space left."""
    if isinstance(error, OSError) and error.errno in (errno.ENOSPC, errno.EDQUOT):
        return True
    if not isinstance(error, (OSError, RuntimeError)):
        return False
    try:
        return shutil.disk_usage(folder).free < _NEARLY_FULL
    except OSError:
        return False


def write_error(path, error):
    """The error to raise for a failed write of `path`: DiskFullError naming it when the
    disk is full, else an OSError that names it (errno kept)."""
    path = Path(path)
    if _disk_full(error, path.parent):
        return DiskFullError(errno.ENOSPC, f'{path}: cannot write: no space left on the '
                             'device (disk full)')
    if isinstance(error, OSError) and str(path) in str(error):
        return error
    return OSError(getattr(error, 'errno', None) or errno.EIO,
                   f'{path}: cannot write: {getattr(error, "strerror", None) or error}')


def _create_temporary(path):
    """(fd, name) of a new file beside `path`, made with mode 0o666 less the umask, as
    open() makes a file (tempfile.mkstemp's 0o600 would leave checkpoints unreadable to the
    detectors of another user reading a shared folder, and to colleagues)."""
    for _ in range(100):
        tmp = path.parent / f'.{path.name}.{secrets.token_hex(4)}.tmp'
        try:
            return os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666), str(tmp)
        except FileExistsError:
            continue
    raise FileExistsError(errno.EEXIST, f'{path}: no free temporary name beside it')


@contextmanager
def atomic_write(path, mode='wb'):
    """Context manager yielding a stream; on success the file appears at `path` whole, on any
    exception (or KeyboardInterrupt) the temporary file is removed and `path` is untouched.
    A write that fails because the disk is full raises DiskFullError (an OSError, ENOSPC)
    naming `path` and saying so, whatever the writer raised."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = _create_temporary(path)
    try:
        with os.fdopen(fd, mode) as stream:
            yield stream
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(tmp, path)
    except BaseException as error:
        full = _disk_full(error, path.parent)   # measured before the temporary file goes
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        if full:
            raise write_error(path, error) from error
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
