"""open_bag: read a rosbag2 MCAP bag folder (metadata.yaml + one or several .mcap files,
split bags) or a bare .mcap file, streaming decoded messages in log-time order.

Memory stays bounded: each file is read chunk by chunk (a chunk's messages are sorted and
held until the next chunk starts), files are merged with a heap. Messages are decoded with
mcap_ros2's decoders built from the schemas stored in the bag (no message packages
needed, e.g. tf2_msgs). Nothing in a damaged bag crashes the reader: undecodable topics,
messages that fail to decode, damaged chunks and truncated files are counted and named in
`reader.report` (a ReadReport) while every readable message is still given; only a bag in
which no message at all can be read (not an MCAP file, or one cut before its first message)
is refused at open, with one line (BagError).
"""
import bisect
from collections import Counter
import contextlib
from dataclasses import dataclass
import heapq
import io
from pathlib import Path
import re

import yaml

from .fast_cdr import fast_decoder
from .mcap_scan import MAGIC, McapScan


class BagError(ValueError):
    """A bag path that cannot be read at all (missing, empty, unreadable, no MCAP files)."""


@dataclass(frozen=True)
class TopicInfo:
    """A topic of the bag: name, message type, message count (None when unknown) and the
    recorded offered QoS profiles (rosbag2's YAML text, or a list in metadata v9)."""
    name: str
    msgtype: str
    count: object = None
    serialization_format: str = 'cdr'
    offered_qos_profiles: object = ''

    @property
    def transient_local(self):
        """True when the recorded publisher was transient-local (latched, e.g. /tf_static)."""
        profiles = self.offered_qos_profiles
        if isinstance(profiles, str):
            try:
                profiles = yaml.safe_load(profiles) if profiles.strip() else []
            except yaml.YAMLError:
                return False
        if not isinstance(profiles, list):
            return False
        return any(isinstance(p, dict) and p.get('durability') in (1, 'transient_local')
                   for p in profiles)


@dataclass
class BagMessage:
    """One message: raw CDR `data` (bytes-like) and, when decoded, `msg` (an object with
    the ROS field names)."""
    topic: str
    msgtype: str
    log_time_ns: int
    publish_time_ns: int
    data: object
    msg: object = None

    @property
    def stamp_ns(self):
        """header.stamp in ns when the decoded message has a header, else the log time."""
        header = getattr(self.msg, 'header', None)
        if header is None:
            return self.log_time_ns
        return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


class ReadReport:
    """What a read gave and what it skipped, by topic and cause."""

    MAX_ERRORS = 200

    def __init__(self, files):
        self.files = [str(f) for f in files]
        self.messages = Counter()          # topic -> messages given
        self.skipped = Counter()           # topic -> messages not given
        self.skip_reasons = {}             # topic -> first reason
        self.undecodable_topics = {}       # topic -> reason (no decoder for its schema)
        self.missing_topics = []           # requested topics the bag does not have
        self.errors = []                   # file-level damage, one line each
        self.error_count = 0
        self.crc_errors = 0
        self.out_of_order = 0              # messages given out of log-time order

    def error(self, file, text):
        self.error_count += 1
        if len(self.errors) < self.MAX_ERRORS:
            self.errors.append(f'{file}: {text}')

    def crc_error(self, file):
        self.crc_errors += 1

    def skip(self, topic, reason, n=1):
        self.skipped[topic] += n
        self.skip_reasons.setdefault(topic, reason)

    @property
    def total_messages(self):
        return sum(self.messages.values())

    @property
    def total_skipped(self):
        return sum(self.skipped.values())

    @property
    def ok(self):
        """True when nothing was skipped, missing or damaged."""
        return not (self.skipped or self.missing_topics or self.error_count or self.crc_errors)

    def summary(self):
        lines = [f'{self.total_messages} messages read from {len(self.files)} file(s), '
                 f'{self.total_skipped} skipped, {self.error_count} file error(s)']
        for topic, n in sorted(self.skipped.items()):
            lines.append(f'  skipped {n} on {topic}: {self.skip_reasons[topic]}')
        for topic in self.missing_topics:
            lines.append(f'  missing topic {topic}')
        lines += [f'  {e}' for e in self.errors[:20]]
        if self.error_count > 20:
            lines.append(f'  ... {self.error_count - 20} more errors')
        if self.out_of_order:
            lines.append(f'  {self.out_of_order} messages out of log-time order')
        return '\n'.join(lines)

    __str__ = summary

    def notice(self, what):
        """'reading <what>: <summary>' when anything was skipped or damaged, else None
        (commands print it, so that no loss goes unsaid)."""
        return None if self.ok else f'reading {what}: {self.summary()}'


def _scan_file(path, first_message_only=False):
    """Read an MCAP file from start to end without its summary: (channels, has_message,
    scan) where channels are the (topic, message type, offered QoS) of every channel record
    (the topics of a file without a usable summary: a recording cut short by a crash or a
    kill has no footer and, from rosbag2, no metadata.yaml either), has_message whether any
    message record could be read, and scan the McapScan (its report names the damage met).
    first_message_only: stop at the first message (channels then incomplete). Damage is
    left to the read that follows (its report)."""
    scan = McapScan(path, ReadReport([path]), False)
    schemas, found, has_message = {}, {}, False
    for event in scan.events(lambda offset: False):
        if event[0] in ('schema', 'channel'):
            defs = [event]
        elif event[0] == 'message':
            defs = []
            has_message = True
        else:
            defs = event[2]
            has_message = has_message or bool(event[3])
        for kind, record in defs:
            if kind == 'schema':
                schemas[record.id] = record
            else:
                found.setdefault(record.id, record)
        if has_message and first_message_only:
            break
    channels = []
    for ch in found.values():
        schema = schemas.get(ch.schema_id)
        channels.append((ch.topic, schema.name if schema else '',
                         ch.metadata.get('offered_qos_profiles', '')))
    return channels, has_message, scan


def _unreadable_line(path, scan):
    """One line: why an MCAP file without a usable summary gives no message at all (not an
    MCAP file, or one cut before its first message), with the scan's first finding."""
    if not _starts_like_mcap(path):
        return (f'{path} is not an MCAP file (it does not start with the MCAP magic and no '
                'message in it can be read): give a rosbag2 folder, a .mcap file or a '
                '`monet synth` folder')
    prefix = f'{path}: '
    found = [e[len(prefix):] if e.startswith(prefix) else e for e in scan.report.errors]
    if scan.size < len(MAGIC):
        found = ['the file ends inside the MCAP magic']
    found = found[:1] + [scan.summary_problem or 'no summary']
    if len(found) == 1:
        found.insert(0, 'no message record')
    return (f'{path} is not a complete MCAP file: no message can be read from its '
            f'{scan.size} bytes ({"; ".join(found)})')


def _natural_key(path):
    return [int(s) if s.isdigit() else s for s in re.split(r'(\d+)', path.name)]


class _Decoders:
    """Decoder per schema (name, encoding, text), built once with mcap_ros2."""

    def __init__(self):
        self._cache = {}

    def get(self, schema, message_encoding):
        """(decode function or None, reason when None, zero_copy: the function takes a
        memoryview)."""
        if message_encoding != 'cdr':
            return None, f'message encoding {message_encoding!r} is not cdr', False
        if schema is None:
            return None, 'the channel has no schema', False
        key = (schema.name, schema.encoding, bytes(schema.data))
        if key not in self._cache:
            self._cache[key] = self._build(schema)
        return self._cache[key]

    @staticmethod
    def _build(schema):
        if schema.encoding != 'ros2msg':
            return (None, f'schema encoding {schema.encoding!r} is not supported '
                          '(ros2msg only)', False)
        try:
            text = bytes(schema.data).decode()
        except UnicodeDecodeError as exc:
            return None, f'schema {schema.name} is not text: {exc}', False
        fast = fast_decoder(schema.name, text)
        if fast is not None:
            return fast, None, True
        from mcap_ros2._dynamic import generate_dynamic
        try:
            with contextlib.redirect_stdout(io.StringIO()), \
                    contextlib.redirect_stderr(io.StringIO()):  # it prints parse errors
                types = generate_dynamic(schema.name, text)
        except Exception as exc:    # noqa: BLE001 - any parser failure: report the topic
            return (None, f'schema {schema.name} does not parse: {type(exc).__name__}: {exc}',
                    False)
        if schema.name not in types:
            return None, f'schema {schema.name} does not define {schema.name}', False
        return types[schema.name], None, False


def _suffix_min_starts(summary):
    """[(chunk offset, min message_start_time over chunks at >= that offset)] from the
    summary's chunk index, by offset."""
    items = sorted((ci.chunk_start_offset, ci.message_start_time)
                   for ci in summary.chunk_indexes)
    out, low = [], None
    for offset, start in reversed(items):
        low = start if low is None else min(low, start)
        out.append((offset, low))
    return out[::-1] or [(0, 0)]


def _start_bound(later_start, offset):
    """Lowest start time of the indexed chunks at or after `offset` (inf if none/unknown)."""
    if not later_start:
        return float('inf')
    k = bisect.bisect_left(later_start, (offset, -1))
    return later_start[k][1] if k < len(later_start) else float('inf')


def _compare_with_summary(summary, read_per_channel, want, path, report):
    """Count, per topic, the messages the summary's statistics list but the scan did not
    read (records lost to damage: a flipped opcode, a cut chunk); reported as skipped."""
    stats = summary.statistics
    if stats is None:
        return
    per_channel = dict(stats.channel_message_counts or {})
    if not per_channel:
        if want is None and stats.message_count > sum(read_per_channel.values()):
            lost = stats.message_count - sum(read_per_channel.values())
            report.error(path, f'{lost} of the {stats.message_count} messages the summary '
                               'lists could not be read (damaged records)')
        return
    for cid, expected in sorted(per_channel.items()):
        channel = summary.channels.get(cid)
        topic = channel.topic if channel is not None else f'<channel {cid}>'
        if want is not None and topic not in want:
            continue
        lost = expected - read_per_channel.get(cid, 0)
        if lost < 0:
            report.error(path, f'{-lost} more messages on {topic} than the summary lists '
                               '(damaged records read as messages?)')
        if lost > 0:
            report.skip(topic, f'{lost} of the {expected} messages that the summary of {path} '
                               'lists could not be read (damaged records; see the errors)', lost)


def _starts_like_mcap(path):
    """Whether the file's first bytes are the MCAP magic (or its start, for a file cut
    shorter than it)."""
    with open(path, 'rb') as f:
        head = f.read(len(MAGIC))
    return MAGIC.startswith(head)


def recording_bag(path):
    """The bag of a recording path: a `monet synth` output folder (a folder holding
    recording/, with rig.yaml, labels.csv, ...) gives its recording/; any other path is the
    bag itself. The one rule for every command (open_bag, learning.find_recording_parts)."""
    path = Path(path)
    return path / 'recording' if path.is_dir() and (path / 'recording').exists() else path


class BagReader:
    """Reader of one bag (see open_bag). Re-iterable; `report` describes the last read."""

    def __init__(self, path, validate_crcs=False, max_buffer_bytes=512 * 2**20):
        self.path = recording_bag(path)
        self.validate_crcs = validate_crcs
        self.max_buffer_bytes = int(max_buffer_bytes)
        self.metadata = None
        self._problems = []
        self.files = self._resolve_files()
        self.report = ReadReport(self.files)
        self._topics = self._collect_topics()
        self._decoders = _Decoders()

    # ------------------------------------------------------------------ opening

    def _resolve_files(self):
        p = self.path
        if not p.exists():
            raise BagError(f'bag path {p} does not exist')
        if p.is_file():
            try:
                size = p.stat().st_size
                with open(p, 'rb'):
                    pass
            except OSError as exc:
                raise BagError(f'bag file {p} is not readable: {exc}') from None
            if size == 0:
                raise BagError(f'bag file {p} is empty')
            if p.suffix.lower() != '.mcap' and not _starts_like_mcap(p):
                raise BagError(f'{p} is not an MCAP file (it does not start with the MCAP '
                               'magic): give a rosbag2 folder, a .mcap file or a `monet '
                               'synth` folder')
            return [p]
        if not p.is_dir():
            raise BagError(f'bag path {p} is neither a file nor a folder')
        try:
            entries = list(p.iterdir())
        except OSError as exc:
            raise BagError(f'bag folder {p} is not readable: {exc}') from None
        files = []
        meta = p / 'metadata.yaml'
        if meta.is_file():
            try:
                from monet_ros.geometry.rig_fields import load_yaml_text  # no aliases
                info = load_yaml_text(meta, meta.read_text())['rosbag2_bagfile_information']
                self.metadata = info
                files = [p / rel for rel in info.get('relative_file_paths') or []]
            except Exception as exc:    # noqa: BLE001 - damaged metadata: fall back to *.mcap
                self._problems.append((str(meta), f'metadata.yaml unusable ({exc}); '
                                                  'reading the .mcap files in the folder'))
                self.metadata = None
            if self.metadata is not None and self.metadata.get('storage_identifier') not in \
                    (None, 'mcap'):
                raise BagError(f'bag {p} uses storage {self.metadata["storage_identifier"]!r};'
                               ' only mcap is supported')
            for f in files:
                if f.suffix in ('.zstd', '.lz4'):
                    raise BagError(f'bag {p}: file-compressed bags ({f.name}) are not '
                                   'supported; decompress first')
            present = [f for f in files if f.is_file() and f.stat().st_size > 0]
            for f in files:
                if f not in present:
                    self._problems.append((str(f), 'listed in metadata.yaml but missing or '
                                                   'empty'))
            files = present
        if not files:
            files = sorted((e for e in entries if e.suffix == '.mcap' and e.is_file()
                            and e.stat().st_size > 0), key=_natural_key)
        if not files:
            raise BagError(f'bag folder {p} has no readable .mcap files')
        return files

    def _collect_topics(self):
        topics = {}
        if self.metadata is not None:
            for entry in self.metadata.get('topics_with_message_count') or []:
                try:
                    md = entry['topic_metadata']
                    topics[md['name']] = TopicInfo(md['name'], md['type'],
                                                   int(entry.get('message_count', 0)),
                                                   md.get('serialization_format', 'cdr'),
                                                   md.get('offered_qos_profiles', ''))
                except (KeyError, TypeError, ValueError):
                    continue
        counts, types, qos, summary_ok = Counter(), {}, {}, True
        unreadable = []          # files without a summary in which no message can be read
        for f in self.files:
            scan = McapScan(f, self.report, self.validate_crcs)
            try:
                with open(f, 'rb') as fh:
                    summary = scan.open_summary(fh)
            except OSError:
                summary = None
            if summary is None:
                summary_ok = False
                # nothing else lists this file's topics without metadata.yaml: all of them;
                # else only whether a message can be read at all
                channels, has_message, scan = _scan_file(f, self.metadata is not None)
                if self.metadata is None:
                    for name, msgtype, profiles in channels:
                        types.setdefault(name, msgtype)
                        qos.setdefault(name, profiles)
                if not has_message:
                    unreadable.append(_unreadable_line(f, scan))
                continue
            for cid, ch in summary.channels.items():
                schema = summary.schemas.get(ch.schema_id)
                types.setdefault(ch.topic, schema.name if schema else '')
                qos.setdefault(ch.topic, ch.metadata.get('offered_qos_profiles', ''))
                if summary.statistics is not None:
                    counts[ch.topic] += summary.statistics.channel_message_counts.get(cid, 0)
        if unreadable and len(unreadable) == len(self.files):   # nothing at all to read
            if len(unreadable) == 1:
                raise BagError(unreadable[0])
            raise BagError(f'bag {self.path}: no message can be read from any of its '
                           f'{len(unreadable)} .mcap files; {unreadable[0]}')
        # the listing is complete when metadata.yaml, every file's summary or a scan of
        # the files without one gave it
        self.topics_complete = True
        for topic, msgtype in types.items():
            if topic not in topics:
                topics[topic] = TopicInfo(topic, msgtype, counts[topic] if summary_ok else None,
                                          'cdr', qos.get(topic, ''))
        return topics

    # ------------------------------------------------------------------ reading

    @property
    def topics(self):
        """topic name -> TopicInfo (from metadata.yaml and the files' summaries)."""
        return dict(self._topics)

    def topics_of_type(self, *msgtypes):
        """Sorted names of the topics with one of these message types."""
        return sorted(t for t, info in self._topics.items() if info.msgtype in msgtypes)

    def messages(self, topics=None, decode=True):
        """BagMessage items in log-time order. topics: names to read (None = all); decode:
        fill `msg` (messages that cannot be decoded are skipped and counted in the report);
        decode=False gives raw CDR only. The report of this read is `self.report`."""
        want = None if topics is None else set([topics] if isinstance(topics, str) else topics)
        report = ReadReport(self.files)
        for file, text in self._problems:
            report.error(file, text)
        if want is not None and self.topics_complete:
            report.missing_topics = sorted(want - set(self._topics))
        self.report = report
        seen = set()
        streams = [self._file_stream(i, f, want, report, seen)
                   for i, f in enumerate(self.files)]
        last = -1
        for item in heapq.merge(*streams):
            log_time, _, _, topic, channel, schema, pub_time, data = item
            if log_time < last:
                report.out_of_order += 1
            last = max(last, log_time)
            msgtype = schema.name if schema is not None else ''
            msg = None
            if decode:
                fn, reason, zero_copy = self._decoders.get(schema, channel.message_encoding)
                if fn is None:
                    report.undecodable_topics.setdefault(topic, reason)
                    report.skip(topic, reason)
                    continue
                try:
                    msg = fn(data if zero_copy else bytes(data))
                except Exception as exc:    # noqa: BLE001 - a bad message costs only itself
                    report.skip(topic, f'decode failed: {type(exc).__name__}: {exc}')
                    continue
            report.messages[topic] += 1
            yield BagMessage(topic, msgtype, log_time, pub_time, data, msg)
        if want is not None:
            report.missing_topics = sorted(want - set(self._topics) - seen)

    def _file_stream(self, index, path, want, report, seen):
        """Messages of one file as sortable tuples, log-time ordered chunk by chunk."""
        scan = McapScan(path, report, self.validate_crcs)
        schemas, channels = {}, {}
        chunk_index = {}

        def skip_chunk(offset):
            summary = scan.summary
            if want is None or summary is None:
                return False
            if not chunk_index:
                chunk_index.update({ci.chunk_start_offset: ci for ci in summary.chunk_indexes})
            ci = chunk_index.get(offset)
            if ci is None or not ci.message_index_offsets:
                return False
            return not any(cid in summary.channels and summary.channels[cid].topic in want
                           for cid in ci.message_index_offsets)

        def resolve(cid):
            # the summary's definitions first (CRC-checked, written last); the data
            # section's where the summary is absent or lacks the id
            summary = scan.summary
            ch = summary.channels.get(cid) if summary is not None else None
            if ch is None:
                ch = channels.get(cid)
            if ch is None:
                return None, None
            schema = summary.schemas.get(ch.schema_id) if summary is not None else None
            if schema is None:
                schema = schemas.get(ch.schema_id)
            return ch, schema

        heap, seq, summary_noted = [], 0, False
        read_per_channel = Counter()  # channel id -> message records read from this file
        held = [0]                # bytes of message data waiting in the heap
        later_start = []          # (offset, min start time of chunks at >= offset) from index

        def push(message):
            nonlocal seq
            cid, _, log_time, pub_time, data = message
            read_per_channel[cid] += 1
            ch, schema = resolve(cid)
            if ch is None:
                report.skip(f'<channel {cid}>', f'message of unknown channel id {cid} in {path}')
                return
            if want is not None and ch.topic not in want:
                return
            if ch.schema_id != 0 and schema is None:
                report.skip(ch.topic, f'schema {ch.schema_id} of {ch.topic} is missing')
                return
            seq += 1
            held[0] += len(data)
            heapq.heappush(heap, (log_time, index, seq, ch.topic, ch, schema, pub_time, data))

        def pop():
            item = heapq.heappop(heap)
            held[0] -= len(item[-1])
            return item

        for event in scan.events(skip_chunk):
            if scan.summary_problem is not None and not summary_noted:
                summary_noted = True
                report.error(path, f'no usable summary/index ({scan.summary_problem}); '
                                   'read sequentially')
            kind = event[0]
            if kind == 'schema':
                schemas[event[1].id] = event[1]
            elif kind == 'channel':
                channels[event[1].id] = event[1]
                seen.add(event[1].topic)
            elif kind == 'message':
                while heap and heap[0][0] <= event[1][2]:
                    yield pop()
                push(event[1])
            else:
                _, start, defs, msgs, offset, _crc_ok = event
                for d_kind, rec in defs:
                    (schemas if d_kind == 'schema' else channels)[rec.id] = rec
                    if d_kind == 'channel':
                        seen.add(rec.topic)
                if scan.summary is not None and not later_start:
                    later_start.extend(_suffix_min_starts(scan.summary))
                # nothing still to come starts before `bound`: release up to it
                bound = min(start, _start_bound(later_start, offset))
                while heap and (heap[0][0] <= bound or held[0] > self.max_buffer_bytes):
                    yield pop()       # (over the memory bound: may come out of order)
                for m in msgs:
                    push(m)
        if scan.summary_problem is not None and not summary_noted:
            report.error(path, f'no usable summary/index ({scan.summary_problem}); '
                               'read sequentially')
        if scan.summary is not None:
            _compare_with_summary(scan.summary, read_per_channel, want, path, report)
        while heap:
            yield pop()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def __repr__(self):
        return (f'BagReader({str(self.path)!r}, files={len(self.files)}, '
                f'topics={len(self._topics)})')


def open_bag(path, validate_crcs=False, max_buffer_bytes=512 * 2**20):
    """A BagReader for a rosbag2 folder (metadata.yaml + .mcap files), a bare .mcap file or
    a `monet synth` output folder (its recording/, recording_bag).

    validate_crcs: also check every chunk's CRC (costs ~1 s per GB on these machines;
    mismatches are reported, the messages still given). The summary's CRC is always
    checked: a damaged summary is not used (the file is read sequentially instead).
    Image / CompressedImage payloads are zero-copy views of the chunk read from disk.
    max_buffer_bytes bounds the message data held per file to restore log-time order
    (chunks written far out of order beyond it come out of order, counted in the report).

    Raises BagError naming the path when it does not exist, is empty or unreadable, holds
    no .mcap file, or when no message at all can be read from it (a file that is not an
    MCAP file, or one cut before its first message: the line names the file, its size and
    the reader's finding); damage inside otherwise readable files never raises (it is
    counted in BagReader.report and every readable message is given)."""
    return BagReader(path, validate_crcs=validate_crcs, max_buffer_bytes=max_buffer_bytes)
