"""No silent loss in the reader: a record or chunk that cannot be read is counted and named,
and `report.ok` is False whenever any message of the file is not given.

Built from issue 14's example (one flipped bit in a record opcode dropped /tf_static with
ok == True; an 8-byte file gave 0 messages and ok): EVERY single-bit flip of EVERY record
opcode of a small real bag (top-level records and the records inside its chunks) is tried.
The layout of the original file comes from the `mcap` library (independent of our scanner).
"""
import io

from helpers.io_bags import make_camera, smooth_images
from helpers.mcap_layout import opcode_offsets
from mcap.reader import make_reader
import numpy as np
import pytest

from monet_ros.io import BagError, BagWriter, open_bag


def build_bag(folder):
    rng = np.random.default_rng(0)
    cams = [make_camera(f'cam{i}', seed=i, size=(16, 12)) for i in range(2)]
    with BagWriter(folder, compression='none', chunk_size=1500) as bag:
        bag.write_tf_static(1000, cams)
        for k in range(6):
            s = 1000 + k * 100
            for cam in cams:
                bag.write_image(f'/{cam.name}/image_raw', s, smooth_images(rng, 1, 12, 16)[0],
                                f'{cam.name}_optical')
    return folder / f'{folder.name}_0.mcap'


@pytest.fixture(scope='module')
def original(tmp_path_factory):
    path = build_bag(tmp_path_factory.mktemp('bag') / 'orig')
    data = path.read_bytes()
    messages = list(make_reader(io.BytesIO(data)).iter_messages())
    return data, len(messages)


def test_reference_bag_reads_whole_and_ok(original, tmp_path):
    data, total = original
    path = tmp_path / 'same.mcap'
    path.write_bytes(data)
    reader = open_bag(path)
    assert len(list(reader.messages(decode=False))) == total == 13
    assert reader.report.ok, reader.report.summary()
    assert reader.report.notice('the bag') is None


def test_every_opcode_bit_flip_is_counted_never_silent(original, tmp_path):
    data, total = original
    offsets = opcode_offsets(data)
    assert len(offsets) > 20
    lossy = 0
    for offset in offsets:
        for bit in range(8):
            damaged = bytearray(data)
            damaged[offset] ^= 1 << bit
            path = tmp_path / 'flip.mcap'
            path.write_bytes(bytes(damaged))
            reader = open_bag(path)
            got = len(list(reader.messages(decode=False)))
            report = reader.report
            where = f'opcode at byte {offset}, bit {bit}: {got}/{total}\n{report.summary()}'
            assert got <= total, where
            if got < total:
                lossy += 1
                assert not report.ok, where
                # each lost message is counted (the summary's statistics say how many)
                assert report.total_skipped >= total - got, where
                assert report.errors, where          # and the damaged record is named
    assert lossy > 0


def test_issue_example_tf_static_lost_is_named(original, tmp_path):
    """The example: the opcode of the first message in the first chunk (the /tf_static
    message) loses a bit -> 0x15."""
    data, total = original
    first_chunk_record = opcode_offsets(data)[2]     # header, first chunk, its first record
    damaged = bytearray(data)
    for offset in opcode_offsets(data):
        if offset > first_chunk_record and data[offset] == 0x05:
            damaged[offset] ^= 0x10
            break
    path = tmp_path / 'flip.mcap'
    path.write_bytes(bytes(damaged))
    reader = open_bag(path)
    got = [m.topic for m in reader.messages(decode=False)]
    assert len(got) == total - 1 and '/tf_static' not in got
    report = reader.report
    assert not report.ok
    assert report.skipped['/tf_static'] == 1
    text = report.summary()
    assert 'opcode 0x15' in text and '/tf_static' in text
    assert report.notice('the bag') == f'reading the bag: {text}'   # what commands print


@pytest.mark.parametrize('size', [0, 8, 20, 60])
def test_short_files_are_not_ok(original, tmp_path, size):
    """An 8-byte file (the magic only) or any cut of the start, before the first message:
    nothing to read, so opening it is a one-line error naming the file and its size (it
    read as a bag without topics: 'no image topic for camera ...')."""
    data, _ = original
    path = tmp_path / 'short.mcap'
    path.write_bytes(data[:size])
    if size == 0:
        with pytest.raises(ValueError, match='empty'):
            open_bag(path)
        return
    with pytest.raises(BagError) as error:
        open_bag(path)
    line = str(error.value)
    assert '\n' not in line
    assert line.startswith(f'{path} is not a complete MCAP file: no message can be read from '
                           f'its {size} bytes (')


def test_seeded_damage_never_loses_messages_silently(original, tmp_path):
    """300 seeded bit flips, overwritten ranges and cuts anywhere in the file: whenever
    fewer messages come back than the file holds, the report is not ok."""
    data, total = original
    rng = np.random.default_rng(314)
    path = tmp_path / 'damaged.mcap'
    silent = []
    for case in range(300):
        buf = bytearray(data)
        kind = int(rng.integers(3))
        if kind == 0:
            for _ in range(int(rng.integers(1, 6))):
                buf[int(rng.integers(len(buf)))] ^= 1 << int(rng.integers(8))
        elif kind == 1:
            i = int(rng.integers(len(buf)))
            n = int(rng.integers(1, 64))
            buf[i:i + n] = rng.integers(0, 256, len(buf[i:i + n]), dtype=np.uint8).tobytes()
        else:
            del buf[int(rng.integers(1, len(buf))):]
        path.write_bytes(bytes(buf))
        try:
            reader = open_bag(path)
        except BagError as exc:          # nothing readable: said at once, naming the file
            assert str(path) in str(exc) and '\n' not in str(exc)
            continue
        got = len(list(reader.messages(decode=False)))
        if got < total and reader.report.ok:
            silent.append((case, kind, got))
    assert not silent, f'messages lost with report.ok True: {silent}'


def test_metadata_yaml_alias_bomb_is_reported_and_the_files_read(original, tmp_path):
    data, total = original
    folder = tmp_path / 'bag'
    folder.mkdir()
    (folder / 'bag_0.mcap').write_bytes(data)
    lines = ['a0: &a0 [x, x, x, x, x, x, x, x, x]']
    lines += [f'a{i}: &a{i} [' + ', '.join([f'*a{i - 1}'] * 9) + ']' for i in range(1, 10)]
    lines.append('rosbag2_bagfile_information: {relative_file_paths: *a9}')
    (folder / 'metadata.yaml').write_text('\n'.join(lines) + '\n')
    reader = open_bag(folder)
    assert len(list(reader.messages(decode=False))) == total
    assert not reader.report.ok and 'alias' in reader.report.summary()
