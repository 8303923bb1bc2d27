"""Real video files for import tests: a variable-frame-rate MP4 (OpenCV's MPEG-4 writer,
then the container's sample durations rewritten so frame j is presented at times[j])."""
import struct

import cv2
import numpy as np

_CONTAINERS = (b'moov', b'trak', b'mdia', b'minf', b'stbl', b'edts')


def _boxes(data, start, end):
    """(type, offset, size) of the ISO-BMFF boxes in data[start:end] (32-bit sizes)."""
    out = []
    while start < end:
        size, kind = struct.unpack('>I4s', data[start:start + 8])
        out.append((kind, start, size))
        start += size
    return out


def _rewrite(data, start, end, edit):
    """data[start:end] with box payloads replaced by edit(kind, payload) (None = keep),
    container sizes recomputed."""
    out = b''
    for kind, offset, size in _boxes(data, start, end):
        if kind in _CONTAINERS:
            payload = _rewrite(data, offset + 8, offset + size, edit)
        else:
            payload = data[offset + 8:offset + size]
            payload = edit(kind, payload) or payload
        out += struct.pack('>I4s', len(payload) + 8, kind) + payload
    return out


def write_vfr_mp4(path, frames_rgb, times_s, nominal_fps=30.0):
    """Write (N, H, W, 3) rgb frames as an MPEG-4 Part 2 MP4 whose frame j has container
    (presentation) time times_s[j] s (strictly increasing, times_s[0] = 0). The last frame
    lasts the median interval. Returns the path. The 'moov' box comes after 'mdat' (OpenCV's
    FFmpeg muxer), so chunk offsets stay valid when it grows."""
    frames = np.asarray(frames_rgb)
    times = np.asarray(times_s, float)
    h, w = frames.shape[1:3]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*'mp4v'), nominal_fps, (w, h))
    for f in frames:
        writer.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    writer.release()
    data = open(path, 'rb').read()
    timescale = {}

    def edit_scale(kind, payload):
        if kind == b'mdhd':
            timescale['media'] = struct.unpack('>I', payload[12:16])[0]
        if kind == b'mvhd':
            timescale['movie'] = struct.unpack('>I', payload[12:16])[0]
    _rewrite(data, 0, len(data), edit_scale)
    ticks = np.round(times * timescale['media']).astype(np.int64)
    deltas = np.diff(ticks)
    deltas = np.append(deltas, int(np.median(deltas)))
    total = int(deltas.sum())
    movie_total = int(round(total * timescale['movie'] / timescale['media']))

    def edit(kind, payload):
        if kind == b'stts':
            body = b''.join(struct.pack('>II', 1, int(d)) for d in deltas)
            return payload[:4] + struct.pack('>I', len(deltas)) + body
        if kind in (b'mdhd', b'mvhd'):
            value = total if kind == b'mdhd' else movie_total
            return payload[:16] + struct.pack('>I', value) + payload[20:]
        if kind == b'tkhd':
            return payload[:20] + struct.pack('>I', movie_total) + payload[24:]
        if kind == b'elst':
            return payload[:8] + struct.pack('>I', movie_total) + payload[12:]
        return None
    with open(path, 'wb') as f:
        f.write(_rewrite(data, 0, len(data), edit))
    return path
