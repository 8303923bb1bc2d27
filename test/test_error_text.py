"""error_text: the one line of a write that failed names the file, also when the error
comes from atomic.write_error (its own words) or from the OS with no file name."""
import errno

import pytest

from monet_ros.atomic import write_error
from monet_ros.error_text import error_line


def _full_disk_error():
    """ENOSPC as the OS raises it (writing to /dev/full): no file name in it."""
    with pytest.raises(OSError) as caught:
        with open('/dev/full', 'wb') as stream:
            stream.write(b'x' * 65536)
            stream.flush()
    assert caught.value.errno == errno.ENOSPC and not caught.value.filename
    return caught.value


def test_a_disk_full_error_of_write_error_keeps_the_path_it_names():
    """write_error's DiskFullError carries the path in its own message (no filename): the
    line used to replace that message by the bare 'no space left on device (disk full)'."""
    error = write_error('/data/runs/m/checkpoints/step_000002.pt', _full_disk_error())
    line = error_line(error, 'monet train', output='/data/runs/m')
    assert line == ('/data/runs/m/checkpoints/step_000002.pt: cannot write: no space left '
                    'on the device (disk full)')


def test_an_os_write_error_without_a_file_names_the_output():
    """The OS names no file when a write into an open file fails: the command's output
    is named, and only for write errors."""
    assert error_line(_full_disk_error(), 'monet process', output='results') == \
        'results: no space left on device (disk full)'
    assert error_line(OSError(errno.EROFS, 'Read-only file system'), 'monet synth',
                      output='rec') == 'rec: read-only file system'
    assert error_line(OSError(errno.EIO, 'Input/output error'), 'monet process',
                      output='results') == 'Input/output error'
    assert error_line(FileNotFoundError(errno.ENOENT, 'No such file or directory', 'a.csv'),
                      'monet triangulate', output='out') == 'a.csv: No such file or directory'
