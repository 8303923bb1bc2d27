"""`monet pipeline` shortens the interpreter's GIL switch interval to 1 ms
(monet_ros.nodes.short_gil_switch), never lengthening one the user shortened further."""
import subprocess
import sys

_PROBE = """
import sys
from monet_ros.nodes import short_gil_switch
if len(sys.argv) > 1:
    sys.setswitchinterval(float(sys.argv[1]))
before = sys.getswitchinterval()
print(before, short_gil_switch(), sys.getswitchinterval())
"""


def _probe(*args):
    out = subprocess.run([sys.executable, '-c', _PROBE, *args], check=True,
                         capture_output=True, text=True).stdout.split()
    return [float(x) for x in out]


def test_default_interval_becomes_one_millisecond():
    before, returned, after = _probe()
    assert before == 0.005          # CPython's default
    assert returned == after and abs(after - 0.001) < 1e-9


def test_a_shorter_interval_is_kept():
    _, returned, after = _probe('0.0002')
    assert returned == after and abs(after - 0.0002) < 1e-9
