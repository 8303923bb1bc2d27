"""One line for an error: what `monet` commands and node executables print when they stop
on bad input (the message names the file / field / option / topic; torch's and others'
multi-line texts are collapsed)."""
import errno
import os
import re

# Terminal styling in library messages (torch bolds a warning): not for a log line.
_ANSI = re.compile(r'\x1b\[[0-9;]*[A-Za-z]')


def os_error_text(error, path=None):
    """One line for an OSError that names the file (the error's, else `path`) and, for a
    full disk or a read-only file system, says so."""
    where = error.filename or path
    reason = error.strerror or str(error)
    if error.errno is not None and reason != os.strerror(error.errno):
        pass                         # our own words (atomic.write_error names the file)
    elif error.errno == errno.ENOSPC:
        reason = 'no space left on device (disk full)'
    elif error.errno == errno.EROFS:
        reason = 'read-only file system'
    if where and not error.filename and str(where) in reason:
        where = None                 # named already
    if error.filename2:
        where = f'{where} -> {error.filename2}'
    return f'{where}: {reason}' if where else reason


# errno values that only a write raises: an error of these that names no file is the
# output's (the OS names none when a write into an open file fails)
WRITE_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EFBIG)


def error_line(error, name='', output=None):
    """The one line printed for a bad-input error (the message names file/field/option);
    a leading `name: ` (the command, already the line's prefix) is not repeated. output:
    the command's output path, named by a write error (full disk, read-only, quota) that
    names no file."""
    if isinstance(error, OSError):
        return os_error_text(error, output if error.errno in WRITE_ERRNOS else None)
    if isinstance(error, MemoryError):
        return 'out of memory (the input or an option asks for too much; see its size)'
    text = ' '.join(_ANSI.sub('', str(error)).split()) or type(error).__name__   # one line
    return text[len(name) + 2:] if name and text.startswith(f'{name}: ') else text
