"""Robust streaming scan of one MCAP file: records in file order, messages per chunk, with
resynchronisation after damage. Used by monet_ros.io.reader (which merges files, sorts by
log time and decodes).

The scan reads the data section record by record. Schema and Channel records are parsed
with the `mcap` library's record classes, the summary with its SeekingReader; chunks and
messages are parsed here so that message payloads are zero-copy memoryviews of the chunk
and a damaged chunk (bad CRC, bad compression, cut records) costs only that chunk. When a
record header is corrupt or the file is cut, scanning resumes at the next chunk the summary
index knows, or else at the next byte offset that parses as a valid chunk header.
"""
import bisect
import io
import os
import struct
import zlib

from mcap.data_stream import ReadDataStream
from mcap.reader import SeekingReader
from mcap.records import Attachment, Channel, Metadata, Schema

MAGIC = b'\x89MCAP0\r\n'
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK = 0x01, 0x02, 0x03, 0x04, \
    0x05, 0x06
OP_MESSAGE_INDEX, OP_ATTACHMENT, OP_METADATA = 0x07, 0x09, 0x0C
OP_DATA_END = 0x0F
_KNOWN_OPS = set(range(0x01, 0x10))
# records that belong in the summary section (or the footer): in the data section, before
# the summary starts, they are damage (e.g. a record whose opcode lost a bit)
_SUMMARY_OPS = {OP_FOOTER, 0x08, 0x0A, 0x0B, 0x0D, 0x0E, OP_DATA_END}
_IN_CHUNK_OPS = (OP_SCHEMA, OP_CHANNEL, OP_MESSAGE)  # the only records a chunk may hold
_CHUNK_FIXED = struct.Struct('<QQQI')          # start, end, uncompressed size, crc
_MSG_HEAD = struct.Struct('<HIQQ')             # channel, sequence, log_time, publish_time
_REC_HEAD = struct.Struct('<BQ')
MAX_UNCOMPRESSED = 1 << 31                     # refuse chunks claiming more than 2 GiB


class ChunkError(ValueError):
    """A chunk that cannot be used (named cause)."""


def read_summary(f, size):
    """The file's Summary via the mcap library, or (None, reason) when absent or damaged
    (the footer's summary CRC is checked, so a summary that is used can be trusted)."""
    try:
        if size < 8 + 29 + 8:
            return None, 'the file is too short for a summary'
        f.seek(size - 8 - 29)
        footer = f.read(29)
        op, length, summary_start, _offsets, crc = struct.unpack('<BQQQI', footer)
        if op != OP_FOOTER or length != 20:
            return None, 'no footer at the end of the file (truncated?)'
        if summary_start == 0:
            return None, 'the file has no summary section'
        if not 8 <= summary_start < size - 8 - 29:
            return None, f'footer points to a summary at byte {summary_start}, outside the file'
        if crc != 0:
            f.seek(summary_start)
            if zlib.crc32(f.read(size - 8 - 29 - summary_start + 1 + 8 + 8 + 8)) != crc:
                return None, 'summary section CRC mismatch'
        f.seek(0)
        summary = SeekingReader(f, record_size_limit=size).get_summary()
    except Exception as exc:        # noqa: BLE001 - any damage means: no usable summary
        return None, f'{type(exc).__name__}: {exc}'
    if summary is None:
        return None, 'the file has no summary section'
    return summary, None


def footer_summary_start(f, size):
    """The footer's summary_start (0 when there is no footer or no summary)."""
    if size < 8 + 29 + 8:
        return 0
    f.seek(size - 8 - 29)
    footer = f.read(29)
    if len(footer) != 29 or footer[0] != OP_FOOTER:
        return 0
    start = struct.unpack_from('<Q', footer, 9)[0]
    return start if 8 <= start < size else 0


def _decompress(compression, data, uncompressed_size):
    if uncompressed_size > MAX_UNCOMPRESSED:
        raise ChunkError(f'chunk claims {uncompressed_size} uncompressed bytes')
    if compression == '':
        if len(data) != uncompressed_size:
            raise ChunkError(f'uncompressed chunk has {len(data)} bytes, header says '
                             f'{uncompressed_size}')
        return data
    if compression == 'zstd':
        import zstandard
        try:
            out = zstandard.ZstdDecompressor().decompress(
                bytes(data), max_output_size=uncompressed_size)
        except zstandard.ZstdError as exc:
            raise ChunkError(f'zstd: {exc}') from None
    elif compression == 'lz4':
        import lz4.frame
        try:
            out = lz4.frame.decompress(bytes(data))
        except RuntimeError as exc:
            raise ChunkError(f'lz4: {exc}') from None
    else:
        raise ChunkError(f'unknown chunk compression {compression!r}')
    if len(out) != uncompressed_size:
        raise ChunkError(f'chunk decompressed to {len(out)} bytes, header says '
                         f'{uncompressed_size}')
    return memoryview(out)


def parse_chunk_header(body):
    """(start, end, uncompressed_size, crc, compression, records memoryview) of a Chunk
    record body; ChunkError when the header is inconsistent."""
    if len(body) < _CHUNK_FIXED.size + 4:
        raise ChunkError('chunk record too short')
    start, end, usize, crc = _CHUNK_FIXED.unpack_from(body, 0)
    off = _CHUNK_FIXED.size
    (clen,) = struct.unpack_from('<I', body, off)
    off += 4
    if clen > 16 or off + clen + 8 > len(body):
        raise ChunkError(f'chunk compression name length {clen} invalid')
    try:
        compression = bytes(body[off:off + clen]).decode('ascii')
    except UnicodeDecodeError:
        raise ChunkError('chunk compression name is not ascii') from None
    off += clen
    (rlen,) = struct.unpack_from('<Q', body, off)
    off += 8
    if off + rlen != len(body):
        raise ChunkError(f'chunk records length {rlen} does not fill the record '
                         f'({len(body) - off} bytes)')
    return start, end, usize, crc, compression, body[off:]


def parse_records(buf, on_error):
    """Records (opcode, body memoryview) in a byte buffer (a chunk's records); stops at the
    first record that runs past the end (on_error(message))."""
    off, n = 0, len(buf)
    while off < n:
        if off + 9 > n:
            on_error(f'{n - off} stray bytes at the end of a chunk')
            return
        op, length = _REC_HEAD.unpack_from(buf, off)
        if off + 9 + length > n:
            on_error(f'record (opcode {op}) at chunk offset {off} runs past the chunk end')
            return
        yield op, buf[off + 9:off + 9 + length]
        off += 9 + length


def parse_message(body):
    """(channel_id, sequence, log_time, publish_time, data memoryview) of a Message body."""
    if len(body) < _MSG_HEAD.size:
        raise ChunkError('message record too short')
    cid, seq, log_time, pub_time = _MSG_HEAD.unpack_from(body, 0)
    return cid, seq, log_time, pub_time, body[_MSG_HEAD.size:]


def parse_schema(body):
    return Schema.read(ReadDataStream(io.BytesIO(bytes(body))))


def parse_channel(body):
    return Channel.read(ReadDataStream(io.BytesIO(bytes(body))))


class McapScan:
    """Stream one MCAP file: `events()` yields ('schema', Schema), ('channel', Channel) and
    ('chunk', start_time, [schema/channel events], [messages], file offset, crc ok) and
    ('message', msg) items in file order, where a message is
    (channel_id, sequence, log_time, publish_time, data).

    report: an object with error(file, text) and crc_error(file) methods.
    skip_chunk(offset): True to seek past the chunk at that file offset without reading it
    (topic filtering with the summary's chunk index). validate_crcs: check chunk CRCs
    (a mismatch is reported; the chunk's messages are still given, each may fail to decode).
    """

    def __init__(self, path, report, validate_crcs=False):
        self.path = str(path)
        self.report = report
        self.validate_crcs = validate_crcs
        self.size = os.path.getsize(self.path)
        self.summary = None
        self.summary_problem = None
        self.summary_start = 0                 # the footer's summary start (0 = unknown)
        self._chunk_offsets = []

    def open_summary(self, f):
        self.summary, self.summary_problem = read_summary(f, self.size)
        self.summary_start = footer_summary_start(f, self.size)
        if self.summary is not None:
            self._chunk_offsets = sorted(
                ci.chunk_start_offset for ci in self.summary.chunk_indexes
                if 8 <= ci.chunk_start_offset < self.size)
        return self.summary

    def _error(self, text):
        self.report.error(self.path, text)

    def _next_start(self, f, after):
        """File offset of the next chunk after `after` to resume at, or None."""
        for off in self._chunk_offsets:
            if off > after and self._looks_like_chunk(f, off):
                return off
        return self._scan_for_chunk(f, after + 1)

    def _looks_like_chunk(self, f, off):
        f.seek(off)
        head = f.read(9 + _CHUNK_FIXED.size + 4 + 16 + 8)
        if len(head) < 9 + _CHUNK_FIXED.size + 4 or head[0] != OP_CHUNK:
            return False
        (length,) = struct.unpack_from('<Q', head, 1)
        if off + 9 + length > self.size:
            return False
        (clen,) = struct.unpack_from('<I', head, 9 + _CHUNK_FIXED.size)
        if clen > 4 or len(head) < 9 + _CHUNK_FIXED.size + 4 + clen + 8:
            return False
        name = head[9 + _CHUNK_FIXED.size + 4:9 + _CHUNK_FIXED.size + 4 + clen]
        if name not in (b'', b'zstd', b'lz4'):
            return False
        (rlen,) = struct.unpack_from('<Q', head, 9 + _CHUNK_FIXED.size + 4 + clen)
        return rlen == length - (_CHUNK_FIXED.size + 4 + clen + 8)

    def _scan_for_chunk(self, f, start, block=1 << 20):
        pos = start
        while pos < self.size:
            f.seek(pos)
            buf = f.read(block + 64)
            if not buf:
                return None
            i = buf.find(b'\x06')
            while 0 <= i < block:
                if self._looks_like_chunk(f, pos + i):
                    return pos + i
                i = buf.find(b'\x06', i + 1)
            pos += block
        return None

    def events(self, skip_chunk=None):
        try:
            f = open(self.path, 'rb')
        except OSError as exc:
            self._error(f'cannot open: {exc}')
            return
        with f:
            if f.read(8) != MAGIC:
                self._error('bad MCAP magic at the start of the file (reading what parses)')
            self.open_summary(f)
            pos, prev, visited = 8, 7, set()
            while pos < self.size:
                f.seek(pos)
                head = f.read(9)
                if len(head) < 9:
                    self._error(f'file ends inside a record header at byte {pos} '
                                '(truncated)')
                    break
                op, length = _REC_HEAD.unpack(head)
                end = pos + 9 + length
                problem = None
                if end > self.size:
                    problem = 'runs past the end of the file (truncated?)'
                elif op not in _KNOWN_OPS and op < 0x80:
                    problem = 'has an unknown opcode'
                elif op in _SUMMARY_OPS:
                    if self._summary_starts_at(f, op, length, pos):
                        break                          # the summary section follows
                    problem = ('is a summary-section record before the end of the data '
                               '(damaged opcode?)')
                else:
                    skipped = self._indexed_chunk_between(pos, end)
                    if skipped is not None:
                        problem = f'would jump over the indexed chunk at byte {skipped}'
                if problem is not None:
                    # resume at the next valid chunk after the last good record start
                    nxt = self._next_start(f, prev)
                    if nxt is None or nxt == pos or nxt in visited:
                        nxt = self._next_start(f, pos)
                    if nxt in visited:
                        nxt = None
                    self._error(f'record at byte {pos} (opcode 0x{op:02x}, length {length}) '
                                f'{problem}; ' + (f'resuming at byte {nxt}' if nxt is not None
                                                  else 'nothing readable after it'))
                    if nxt is None:
                        break
                    visited.add(nxt)
                    prev, pos = pos, nxt
                    continue
                if op == OP_CHUNK:
                    if skip_chunk is not None and skip_chunk(pos):
                        prev, pos = pos, end
                        continue
                    body = memoryview(f.read(length))
                    item = self._chunk(body, pos)
                    if item is None:                   # damaged chunk: find the next one
                        nxt = self._next_start(f, pos)
                        if nxt is None:
                            break
                        prev, pos = pos, nxt
                        continue
                    yield item
                elif op == OP_MESSAGE and self._chunk_offsets:
                    # the summary indexes chunks: its messages are all in chunks, so this is
                    # another record whose opcode was damaged (e.g. a message index)
                    self._error(f'record at byte {pos} (opcode 0x05, length {length}) is a '
                                'message outside the chunks of a chunked file (damaged); '
                                'skipped')
                elif op in (OP_SCHEMA, OP_CHANNEL, OP_MESSAGE):
                    body = memoryview(f.read(length))
                    item = self._record(op, body, pos)
                    if item is not None:
                        yield item
                else:
                    trouble = self._check_other(op, memoryview(f.read(length)), pos)
                    if trouble is not None:
                        self._error(f'record at byte {pos} (opcode 0x{op:02x}, length '
                                    f'{length}) {trouble}; skipped')
                prev, pos = pos, end

    def _summary_starts_at(self, f, op, length, pos):
        """True when the record at `pos` (a summary-section opcode) is where the data ends:
        at or after the footer's summary start (or the data end record just before it)
        when the footer gives one, else when no chunk follows it."""
        if op == OP_DATA_END and length != 4 or op == OP_FOOTER and length != 20:
            return False
        if self.summary_start:
            return pos >= self.summary_start or (op == OP_DATA_END
                                                 and pos + 9 + 4 == self.summary_start)
        return (self._indexed_chunk_between(pos, self.size) is None
                and self._scan_for_chunk(f, pos + 1) is None)

    def _indexed_chunk_between(self, lo, hi):
        """An indexed chunk offset strictly inside (lo, hi) that really holds a chunk."""
        k = bisect.bisect_right(self._chunk_offsets, lo)
        while k < len(self._chunk_offsets) and self._chunk_offsets[k] < hi:
            off = self._chunk_offsets[k]
            with open(self.path, 'rb') as g:
                if self._looks_like_chunk(g, off):
                    return off
            k += 1
        return None

    def _check_other(self, op, body, pos):
        """Problem text for a data-section record that is not a schema/channel/message/chunk
        (message index, attachment, metadata, header, private), or None when it is valid."""
        if op == OP_HEADER:
            return None if pos == 8 else 'is a second file header (damaged)'
        if op == OP_MESSAGE_INDEX:
            if len(body) < 6:
                return 'is a message index too short to parse (damaged)'
            (n,) = struct.unpack_from('<I', body, 2)
            if n % 16 or 6 + n != len(body):
                return 'is a message index whose entries do not fill it (damaged)'
            return None
        if op in (OP_ATTACHMENT, OP_METADATA):
            try:
                stream = ReadDataStream(io.BytesIO(bytes(body)))
                (Attachment if op == OP_ATTACHMENT else Metadata).read(stream)
            except Exception as exc:    # noqa: BLE001 - any parse failure is damage
                return f'does not parse: {type(exc).__name__}: {exc}'
            return None
        return 'has a private opcode (not written by rosbag2; damaged?)'

    def _record(self, op, body, pos):
        try:
            if op == OP_SCHEMA:
                return ('schema', parse_schema(body))
            if op == OP_CHANNEL:
                return ('channel', parse_channel(body))
            return ('message', parse_message(body))
        except Exception as exc:    # noqa: BLE001 - a damaged record costs only itself
            self._error(f'record at byte {pos} (opcode {op}) does not parse: {exc}')
            return None

    def _chunk(self, body, pos):
        try:
            start, end, usize, crc, compression, data = parse_chunk_header(body)
            data = _decompress(compression, data, usize)
        except (ChunkError, struct.error) as exc:
            self._error(f'chunk at byte {pos} skipped: {exc}')
            return None
        crc_ok = True
        if self.validate_crcs and crc != 0 and zlib.crc32(data) != crc:
            crc_ok = False
            self.report.crc_error(self.path)
            self._error(f'chunk at byte {pos}: CRC mismatch (data damaged; messages kept, '
                        'each may fail to decode)')
        messages, defs = [], []
        ranged = 0 < end and start <= end          # the header's message time range
        records = parse_records(data, lambda t: self._error(f'chunk at byte {pos}: {t}'))
        for k, (op, rec) in enumerate(records):
            if op not in _IN_CHUNK_OPS:
                self._error(f'chunk at byte {pos}: record {k} has opcode 0x{op:02x}, which a '
                            'chunk cannot hold (damaged); skipped')
                continue
            item = self._record(op, rec, pos)
            if item is None:
                continue
            if item[0] == 'message':
                if ranged and not start <= item[1][2] <= end:
                    # e.g. a Channel record whose opcode became 0x05 parses as a "message"
                    self._error(f'chunk at byte {pos}: record {k} is a message with log time '
                                f"{item[1][2]} outside the chunk's range {start}..{end} "
                                '(damaged); skipped')
                    continue
                messages.append(item[1])
            else:
                defs.append(item)
        return ('chunk', start, defs, messages, pos, crc_ok)
