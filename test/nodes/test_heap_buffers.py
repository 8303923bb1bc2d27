"""Large message buffers come from the heap in every node process
(monet_ros.nodes.heap_for_large_buffers), where glibc by default maps a fresh region for
each buffer over 128 KB (and faults its pages in again for every message)."""
import os
import subprocess
import sys

# In a fresh interpreter: where does a frame-sized (640x480 rgb8) buffer live?
_PROBE = """
import ctypes, sys
from monet_ros.nodes import heap_for_large_buffers
applied = heap_for_large_buffers() if sys.argv[1] == '1' else None
buf = bytearray(640 * 480 * 3 + 80)
address = ctypes.addressof(ctypes.c_char.from_buffer(buf))
with open('/proc/self/maps') as maps:
    for line in maps:
        if line.rstrip().endswith('[heap]'):
            lo, hi = (int(x, 16) for x in line.split()[0].split('-'))
            print(applied, lo <= address < hi)
            break
    else:
        print(applied, False)
"""


def _probe(heap, env=None):
    out = subprocess.run([sys.executable, '-c', _PROBE, '1' if heap else '0'], check=True,
                         capture_output=True, text=True, env=env).stdout.split()
    return out[0], out[1] == 'True'


def test_a_frame_buffer_comes_from_the_heap():
    assert _probe(heap=False) == ('None', False)      # glibc's default: a mapping of its own
    assert _probe(heap=True) == ('True', True)


def test_a_users_allocator_settings_are_kept():
    env = dict(os.environ, MALLOC_MMAP_THRESHOLD_='131072')
    assert _probe(heap=True, env=env) == ('False', False)
