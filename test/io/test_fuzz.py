"""Fuzz: seeded truncations, bit flips and overwritten byte ranges of a small bag never
crash or hang the reader, and every message of an untouched chunk still comes back."""
import os
import signal

from helpers.io_bags import make_camera, smooth_images
from mcap.data_stream import ReadDataStream
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import breakup_chunk
import numpy as np
import pytest

from monet_ros.io import BagError, BagWriter, iter_multiview_frames, open_bag, rig_from_bag

CASES = 300
SECONDS_PER_CASE = 10


def build_bag(folder, compression):
    rng = np.random.default_rng(0)
    cams = [make_camera(f'cam{i}', seed=i, size=(16, 12)) for i in range(2)]
    with BagWriter(folder, compression=compression, chunk_size=1500) as bag:
        bag.write_tf_static(1000, cams)
        for k in range(12):
            s = 1000 + k * 100
            for cam in cams:
                bag.write_image(f'/{cam.name}/image_raw', s, smooth_images(rng, 1, 12, 16)[0],
                                f'{cam.name}_optical')
                bag.write_camera_info(f'/{cam.name}/camera_info', s, cam, f'{cam.name}_optical')
            bag.write('/chatter', 'std_msgs/msg/String',
                      bag.message('std_msgs/msg/String', data=f'msg {k}'), s)
    return folder / f'{folder.name}_0.mcap'


def bag_layout(data):
    """Where everything lives in the original file, via the mcap library (independent of
    our scanner): chunks [(lo, hi, [(log_time, payload, channel id)])], the byte range of
    each channel's Channel record and of its Schema record, and the summary's start."""
    import io
    reader = make_reader(io.BytesIO(data))
    summary = reader.get_summary()
    chunks, where = [], {}
    for ci in summary.chunk_indexes:
        lo, hi = ci.chunk_start_offset, ci.chunk_start_offset + ci.chunk_length
        chunk = Chunk.read(ReadDataStream(io.BytesIO(data[lo + 9:hi])))
        msgs = []
        for r in breakup_chunk(chunk):
            if isinstance(r, Message):
                msgs.append((r.log_time, bytes(r.data), r.channel_id))
            elif isinstance(r, Channel):
                where[('channel', r.id)] = (lo, hi)
            elif isinstance(r, Schema):
                where[('schema', r.id)] = (lo, hi)
        chunks.append((lo, hi, msgs))
    schema_of = {c.id: c.schema_id for c in summary.channels.values()}
    footer_start = len(data) - 8 - 29
    summary_start = int.from_bytes(data[footer_start + 9:footer_start + 17], 'little')
    return chunks, where, schema_of, summary_start


def intact_messages(chunks, where, schema_of, summary_start, original, data, damaged, cut):
    """[(chunk offset, log_time, payload)] of the messages a damaged file still holds
    whole: in a chunk neither cut nor touched, with their channel and schema definitions
    intact (in their chunk, or the summary)."""
    end = len(data) if cut is None else cut

    def intact(lo, hi):
        return hi <= end and not any(a < hi and b > lo for a, b in damaged)
    summary_ok = intact(summary_start, len(original))
    out = []
    for lo, hi, msgs in chunks:
        if not intact(lo, hi):
            continue
        for log_time, payload, cid in msgs:
            defs = [where[('channel', cid)], where[('schema', schema_of[cid])]]
            if summary_ok or all(intact(*d) for d in defs):
                out.append((lo, log_time, payload))
    return out


class Timeout(Exception):
    pass


def _alarm(signum, frame):
    raise Timeout()


def mutate(data, rng):
    """(mutated bytes, list of damaged byte ranges [lo, hi), truncation length or None)."""
    buf = bytearray(data)
    kind = rng.integers(4)
    damaged, cut = [], None
    if kind in (0, 3):                               # truncate
        cut = int(rng.integers(0, len(buf)))
        del buf[cut:]
    if kind in (1, 3):                               # flip bits
        for _ in range(int(rng.integers(1, 9))):
            if not buf:
                break
            i = int(rng.integers(len(buf)))
            buf[i] ^= 1 << int(rng.integers(8))
            damaged.append((i, i + 1))
    if kind == 2 and buf:                            # overwrite a range with random bytes
        i = int(rng.integers(len(buf)))
        n = int(rng.integers(1, 64))
        buf[i:i + n] = rng.integers(0, 256, len(buf[i:i + n]), dtype=np.uint8).tobytes()
        damaged.append((i, i + n))
    return bytes(buf), damaged, cut


@pytest.mark.parametrize('compression', ['none', 'zstd'])
def test_fuzzed_bags_never_crash_or_hang(tmp_path, compression):
    original = build_bag(tmp_path / 'orig', compression).read_bytes()
    chunks, where, schema_of, summary_start = bag_layout(original)
    assert len(chunks) >= 5 and sum(len(c[2]) for c in chunks) == 1 + 12 * 5
    assert 0 < summary_start < len(original)
    seed = int(os.environ.get('MONET_FUZZ_SEED', 1234)) + (compression == 'zstd')
    rng = np.random.default_rng(seed)     # MONET_FUZZ_SEED=<n> for a different soak run
    old = signal.signal(signal.SIGALRM, _alarm)
    stats = {'open_error': 0, 'cases': 0, 'expected': 0}
    try:
        for case in range(CASES // 2):
            data, damaged, cut = mutate(original, rng)
            path = tmp_path / f'case{case}.mcap'
            path.write_bytes(data)
            # every message of an intact chunk (not cut, no damaged byte) comes back when
            # its channel and schema definitions are intact, in their chunk or the summary
            expected = intact_messages(chunks, where, schema_of, summary_start, original,
                                       data, damaged, cut)
            signal.alarm(SECONDS_PER_CASE)
            try:
                try:
                    reader = open_bag(path, validate_crcs=bool(case % 2))
                except BagError as exc:
                    # only a file with nothing to read: empty, or no message readable
                    stats['open_error'] += 1
                    assert not expected, f'case {case}: BagError with intact messages: {exc}'
                    assert '\n' not in str(exc) and str(path) in str(exc)
                    continue
                raw = [(m.log_time_ns, bytes(m.data)) for m in reader.messages(decode=False)]
                decoded = list(reader.messages())
                topics = ['/cam0/image_raw', '/cam1/image_raw']
                frames = list(iter_multiview_frames(reader, topics))
                try:
                    rig_from_bag(reader)
                except ValueError as exc:        # RigFromBagError / CameraError: named
                    assert 'cam' in str(exc) or 'bag' in str(exc), exc
                assert reader.report.summary()
            except Timeout:
                pytest.fail(f'case {case}: reader hung (> {SECONDS_PER_CASE} s)')
            finally:
                signal.alarm(0)
            stats['cases'] += 1
            assert len(decoded) <= len(raw)
            assert all(not set(f.images) & set(f.missing) for f in frames)
            got = set(raw)
            for lo, log_time, payload in expected:
                stats['expected'] += 1
                assert (log_time, payload) in got, (
                    f'case {case}: message at {log_time} of the intact chunk at byte {lo} '
                    f'lost; report:\n{reader.report}')
    finally:
        signal.signal(signal.SIGALRM, old)
    # a BagError only for the files with nothing to read (cut before the first message)
    assert stats['cases'] + stats['open_error'] == CASES // 2
    assert stats['cases'] >= CASES // 2 - 30 and stats['expected'] > 1000
