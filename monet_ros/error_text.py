"""One line for an error: what `monet` commands and node executables print when they stop
on bad input (the message names the file / field / option / topic; torch's and others'
multi-line texts are collapsed)."""
import errno
import re

# Terminal styling in library messages (torch bolds a warning): not for a log line.
_ANSI = re.compile(r'\x1b\[[0-9;]*[A-Za-z]')


def os_error_text(error, path=None):
    """One line for an OSError that names the file (the error's, else `path`) and, for a
    full disk or a read-only file system, says so."""
    where = error.filename or path
    reason = error.strerror or str(error)
    if error.errno == errno.ENOSPC:
        reason = 'no space left on device (disk full)'
    elif error.errno == errno.EROFS:
        reason = 'read-only file system'
    if error.filename2:
        where = f'{where} -> {error.filename2}'
    return f'{where}: {reason}' if where else reason


def error_line(error, name=''):
    """The one line printed for a bad-input error (the message names file/field/option);
    a leading `name: ` (the command, already the line's prefix) is not repeated."""
    if isinstance(error, OSError):
        return os_error_text(error)
    if isinstance(error, MemoryError):
        return 'out of memory (the input or an option asks for too much; see its size)'
    text = ' '.join(_ANSI.sub('', str(error)).split()) or type(error).__name__   # one line
    return text[len(name) + 2:] if name and text.startswith(f'{name}: ') else text
