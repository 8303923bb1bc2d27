"""`monet import videos SESSION --calibration CAL --out REC`: per-camera videos (or image
folders) + a calibration -> a rosbag2 MCAP recording that every `monet` command and the
player read.

    monet import videos SESSION_DIR --calibration calibration.toml --out rec
        [--fps 60] [--offsets cam01=3] [--resize 0.5] [--compressed|--raw]
        [--format jpeg|png] [--camera-map cam_01=cam01] [--start-ns N] [--timing container]

- SESSION_DIR holds one video per camera (any file OpenCV/FFmpeg decodes: .mp4, .avi,
  .mkv, .mov, ...), one folder of images per camera (.png/.jpg), or one folder per camera
  holding its video (sleap-anipose's layout SESSION/back/minimal_back.mp4: the folder's
  name is the entry's, its subfolders such as calibration_images/ are not read). A camera of the
  calibration (any monet_ros.geometry.load_rig format) is matched to the entry whose name
  contains the camera name, as anipose does (the longest camera name wins, so cam1 does
  not take cam10's file); --camera-map renames calibration cameras first (Pose2Sim's
  cam_01 -> cam01 for files cam01.mp4). Every camera must match exactly one entry (else
  exit 2 naming the camera and the entries); entries no camera matches are listed and
  ignored.
- Instants (monet_ros.io.frame_sources): an image is the instant of the number in its
  file name (frame_0004.png -> 4, counted from the session's smallest number; names
  without numbers: name order, with a note); a video frame is the instant nearest its
  container time at the instant rate (round(time * fps); the frame index for a constant
  frame rate video; --timing index: always the index). A file or frame that is not there
  is a missing view at its instant; a second frame nearest one instant (VFR) is dropped;
  both are counted and printed, and a variable-frame-rate video is named with how its
  frames were placed.
- Stamps: stamp of instant i = start + round(i * 1e9 / fps) ns, the same for every
  camera's view of it; --offsets cam=N: camera c's instant N becomes instant 0 (its
  first N dropped), N < 0 delays it by |N| instants. fps (the instant rate): --fps, else
  the videos' own rate (they must agree; image folders need --fps).
- Topics per camera NAME: /NAME/image_raw/compressed (CompressedImage, the default;
  --format jpeg|png, png is lossless) or, with --raw, /NAME/image_raw (Image rgb8,
  lossless), /NAME/camera_info every frame (K, D, size; frame NAME_optical), and one
  /tf_static (world -> NAME_optical), in metres as ROS has it (REP 103): a calibration in
  mm or cm (its `units`, --rig-units, else the rule of monet_ros.geometry.units) is
  converted, with a note.
- Image size (monet_ros.io.rig_fit.fit_camera): the calibration's size must be the
  video's. When the video is the calibration scaled by s (both axes), K is scaled
  (c' = (c + 0.5) s - 0.5). When it differs by at most 16 px (codec padding: Pose2Sim's
  demo videos are 1080 wide, its calibration says 1088), the video's size is used with K
  unchanged and a note. Any other difference is an error. --resize s scales images and
  calibration together (cv2.INTER_AREA; Camera.crop of the full frame, the same mapping
  as cv2.resize); the videos' and the recorded sizes are kept in OUT/monet_import.yaml
  (io.source_sizes), from which `monet labels import` scales labels made on the videos.
- Frames are streamed one instant at a time (memory: one frame per camera); a tqdm
  progress bar shows the instants written. A failed or interrupted import removes its
  output folder, so the same command can be rerun.
"""
from pathlib import Path
import shutil
import sys

import numpy as np

from monet_ros.io.frame_sources import FrameSourceError

HELP = 'videos (or image folders) + calibration -> a rosbag2 MCAP recording'
DEFAULT_START_NS = 1_767_225_600_000_000_000          # 2026-01-01T00:00:00Z
TIMINGS = ('container', 'index')


class ImportVideoError(FrameSourceError):
    """A session, calibration or option that cannot be imported; the message names it."""


def add_arguments(parser):
    sub = parser.add_subparsers(dest='import_command', metavar='WHAT')
    sub.required = True
    p = sub.add_parser('videos', help=HELP, description=__doc__.split('\n\n')[0])
    p.add_argument('session', help='folder with one video (or image folder) per camera')
    p.add_argument('--calibration', required=True, help='calibration / rig file (any format '
                   'monet_ros.geometry.load_rig reads: anipose/Pose2Sim TOML, rig YAML, ...)')
    from monet_ros.commands.common import add_rig_units_argument
    add_rig_units_argument(p)
    p.add_argument('--out', required=True, help='output rosbag2 folder (must not exist)')
    p.add_argument('--fps', type=float, default=None, help='instant rate (default: the '
                   "videos'); video frames go to the instant nearest their container time")
    p.add_argument('--timing', choices=TIMINGS, default='container',
                   help='video frame -> instant: container time (default) or frame index '
                   '(a slow-motion file whose container rate is not the capture rate)')
    p.add_argument('--offsets', action='append', default=[], metavar='CAM=N',
                   help="drop camera CAM's first N frames (negative: delay it); repeatable")
    p.add_argument('--resize', type=float, default=1.0, help='scale images and calibration '
                   '(0 < s <= 1, e.g. 0.5)')
    group = p.add_mutually_exclusive_group()
    group.add_argument('--compressed', dest='transport', action='store_const',
                       const='compressed', help='CompressedImage topics (default)')
    group.add_argument('--raw', dest='transport', action='store_const', const='raw',
                       help='raw Image rgb8 topics')
    p.set_defaults(transport='compressed')
    p.add_argument('--format', choices=('jpeg', 'png'), default=None,
                   help='compression of the CompressedImage topics (default jpeg; png is '
                   'lossless)')
    p.add_argument('--quality', type=int, default=90, help='JPEG quality 1..100')
    p.add_argument('--camera-map', action='append', default=[], metavar='SRC=DST',
                   help='rename calibration cameras (e.g. cam_01=cam01); repeatable')
    p.add_argument('--start-ns', type=int, default=DEFAULT_START_NS,
                   help='stamp of instant 0 (ns; default 2026-01-01T00:00:00Z)')
    p.add_argument('--max-frames', type=int, default=0, help='import at most N instants '
                   '(0 = all)')
    p.add_argument('--quiet', action='store_true', help='no progress bar')


def _offsets(items, names):
    out = {}
    for item in items:
        for part in str(item).split(','):
            name, sep, value = part.partition('=')
            try:
                out[name.strip()] = int(value)
            except ValueError:
                raise ImportVideoError(f'--offsets: {part!r} is not CAMERA=FRAMES') from None
            if not sep or name.strip() not in names:
                raise ImportVideoError(f'--offsets: {part!r}: camera {name.strip()!r} is not '
                                       f'one of {", ".join(names)}')
    return out


def _check_options(fps, resize, quality, start_ns, max_frames, timing):
    """ImportVideoError naming the first option out of its range."""
    if not 0 < resize <= 1:
        raise ImportVideoError(f'--resize must be in (0, 1], got {resize}')
    if fps is not None and not (np.isfinite(fps) and fps > 0):
        raise ImportVideoError(f'--fps must be a finite number > 0 (frames/s), got {fps}')
    if not 1 <= int(quality) <= 100:
        raise ImportVideoError(f'--quality must be in 1..100, got {quality}')
    if int(start_ns) < 0:
        raise ImportVideoError(f'--start-ns must be >= 0 ns, got {start_ns}')
    if int(max_frames) < 0:
        raise ImportVideoError(f'--max-frames must be >= 0 (0 = every instant), got '
                               f'{max_frames}')
    if timing not in TIMINGS:
        raise ImportVideoError(f'--timing must be one of {", ".join(TIMINGS)}, got {timing!r}')


class _Placer:
    """Frames of one FrameSource, each at its instant (module docstring), one ahead."""

    def __init__(self, source, fps, timing, base, offset):
        self.source, self.fps, self.timing, self.base, self.offset = (source, fps, timing,
                                                                      base, offset)
        self.skipped = 0            # frames before instant 0 (offsets)
        self.dropped = 0            # a second frame nearest an instant already given
        self.missing = 0            # instants (up to the last written) without this view
        self.worst_ms = 0.0         # largest |container time - instant time| kept
        self.pending = self._next()

    def _instant(self, key):
        """(instant before the offset, |time - instant time| ms) of a frame key."""
        src = self.source
        if src.kind == 'images':
            return key - (self.base if src.numbered else 0), 0.0
        if self.timing == 'index' or not src.times_ok:
            return src.position - 1, 0.0
        instant = int(round(key * self.fps / 1000.0))
        return instant, abs(key - instant * 1000.0 / self.fps)

    def _next(self):
        while True:
            item = self.source.read()
            if item is None:
                return None
            instant, off_ms = self._instant(item[0])
            if instant - self.offset < 0:
                self.skipped += 1
                continue
            return instant - self.offset, off_ms, item[1]

    def take(self, t):
        """The image of instant t or None (a missing view, counted). Of several frames
        nearest instant t the one nearest in time is kept, the others are dropped."""
        while self.pending is not None and self.pending[0] < t:
            self.dropped += 1          # a guard: instants never go back (FrameSource)
            self.pending = self._next()
        if self.pending is None or self.pending[0] > t:
            self.missing += 1
            return None
        best = self.pending
        self.pending = self._next()
        while self.pending is not None and self.pending[0] == t:
            self.dropped += 1
            if self.pending[1] < best[1]:
                best = self.pending
            self.pending = self._next()
        self.worst_ms = max(self.worst_ms, best[1])
        return best[2]

    def remaining(self):
        """Read and count the frames left (after --max-frames)."""
        count = 0 if self.pending is None else 1
        while self.source.read() is not None:
            count += 1
        self.pending = None
        return count


def _rate(names, sources, files, fps):
    """The instant rate: --fps, else the videos' agreeing nominal rate."""
    if fps is not None:
        return float(fps)
    rates = {n: s.fps for n, s in sources.items() if s.fps}
    if len(rates) != len(names):
        raise ImportVideoError('--fps is needed: ' + ', '.join(
            str(files[n]) for n in names if n not in rates) + ' has no frame rate')
    if max(rates.values()) - min(rates.values()) > 1e-3 * max(rates.values()):
        raise ImportVideoError('the videos disagree on the frame rate ('
                               + ', '.join(f'{n} {r:g}' for n, r in rates.items())
                               + '); give --fps (the instant rate: frames go to the instant '
                               'nearest their container time)')
    return float(np.median(list(rates.values())))


def _timing_notes(placers, files, fps, timing, fps_given):
    notes = []
    for name, p in placers.items():
        src = p.source
        if src.kind != 'video':
            continue
        if not src.times_ok and src.position > 1:
            notes.append(f'{files[name]}: no container timestamps: frames stamped by index '
                         f'at {fps:g} fps')
        elif src.variable_rate:
            low, high = src.intervals_ms
            grid = f'--fps {fps:g}' if fps_given else f"the videos' {fps:g} fps"
            how = (f'--timing index stamped its frames by index at {fps:g} fps (container '
                   'times ignored)' if timing == 'index' else
                   f'{grid} is the instant grid: each frame went to the instant nearest its '
                   f'container time (at most {p.worst_ms:.1f} ms off), not to its index')
            notes.append(f'{files[name]} has a variable frame rate (frame intervals '
                         f'{low:.1f}..{high:.1f} ms): {how}')
        elif timing == 'container' and src.fps and abs(src.fps - fps) > 1e-3 * fps:
            notes.append(f'{files[name]} is {src.fps:g} fps, the instant rate {fps:g} fps: '
                         'frames placed by container time (use --timing index to stamp '
                         'every frame by its index instead)')
    return notes


def import_videos(session, calibration, out, fps=None, offsets=(), resize=1.0, raw=False,
                  fmt='jpeg', quality=90, camera_map=(), start_ns=DEFAULT_START_NS,
                  max_frames=0, progress=True, timing='container', rig_units=None):
    """Write the recording (module docstring). rig_units: the calibration's length unit
    when the file states none. Returns a dict: cameras (Camera list as written, in m),
    files {camera: path}, instants, stamps (first, last), fps, notes, skipped {camera:
    frames not imported: before instant 0 by offsets, beyond --max-frames}, missing
    {camera: instants without its view}, dropped {camera: frames sharing an instant with an
    earlier one}, counts {camera: frames read}. Raises ImportVideoError
    (a ValueError) naming the file or option."""
    from tqdm import tqdm

    from monet_ros.geometry import load_rig
    from monet_ros.geometry.units import rescale
    from monet_ros.io import BagWriter
    from monet_ros.io.frame_sources import FrameSource, session_entries
    from monet_ros.io.rig_fit import fit_camera
    from monet_ros.io.source_sizes import write_source_sizes
    from monet_ros.labels import match_camera_names, parse_name_map

    _check_options(fps, resize, quality, start_ns, max_frames, timing)
    if Path(out).exists():
        raise ImportVideoError(f'{out}: output exists; choose a new folder')
    rename = dict(parse_name_map(camera_map, 'camera'))
    cameras = [c.replace(name=rename.get(c.name, c.name), topic=None)
               for c in load_rig(calibration, units=rig_units)]
    names = [c.name for c in cameras]
    entries = session_entries(session)
    files = {cam: entries[e] for cam, e in match_camera_names(names, list(entries)).items()}
    shifts = _offsets(offsets, names)
    sources = {}
    notes, final = [], []
    try:
        for n in names:
            sources[n] = FrameSource(files[n])
        rate = _rate(names, sources, files, fps)
        firsts = [s.first_number for s in sources.values() if s.first_number is not None]
        base = min(firsts) if firsts else 0
        notes += [s.order_note for s in sources.values() if s.order_note]
        for cam in cameras:
            src = sources[cam.name]
            fitted, note = fit_camera(cam, src.width, src.height, files[cam.name])
            if note:
                notes.append(note)
            if resize != 1.0:
                size = (max(1, round(src.width * resize)), max(1, round(src.height * resize)))
                fitted = fitted.crop((0, 0, fitted.width, fitted.height), size)
            final.append(fitted.replace(topic=(f'/{cam.name}/image_raw' if raw
                                               else f'/{cam.name}/image_raw/compressed')))
        placers = {n: _Placer(sources[n], rate, timing, base, shifts.get(n, 0))
                   for n in names}
        spans = [(s.numbers[-1] - base if s.kind == 'images' and s.numbered else s.count - 1)
                 - shifts.get(n, 0) + 1 for n, s in sources.items()]
        total = max(max(spans), 0)
        if max_frames:
            total = min(total, int(max_frames))
        period = 1e9 / rate
        stamps = []
        if final[0].units != 'm':
            notes.append(f'{calibration} is in {final[0].units}: /tf_static written in metres '
                         '(ROS REP 103); 3D from this recording is in m')
            final = rescale(final, 'm')
        with BagWriter(out) as writer:
            writer.write_tf_static(int(start_ns), final)
            bar = tqdm(total=total or None, desc='monet import videos', unit='instant',
                       disable=not progress, file=sys.stderr)
            t = 0
            while any(p.pending is not None for p in placers.values()) and \
                    (not max_frames or t < max_frames):
                stamp = int(start_ns) + int(round(t * period))
                wrote = False
                for cam in final:
                    image = placers[cam.name].take(t)
                    if image is None:
                        continue
                    if (image.shape[1], image.shape[0]) != (cam.width, cam.height):
                        import cv2
                        image = cv2.resize(image, (cam.width, cam.height),
                                           interpolation=cv2.INTER_AREA)
                    frame_id = f'{cam.name}_optical'
                    if raw:
                        writer.write_image(cam.topic, stamp, image, frame_id)
                    else:
                        writer.write_compressed_image(cam.topic, stamp, image, frame_id,
                                                      fmt=fmt, quality=quality)
                    writer.write_camera_info(f'/{cam.name}/camera_info', stamp, cam, frame_id)
                    wrote = True
                if wrote:
                    stamps.append(stamp)
                else:                  # no camera has this instant: not in the recording
                    for p in placers.values():
                        p.missing -= 1
                bar.update(1)
                t += 1
            bar.close()
        # the videos' size beside the recorded one: monet labels import brings labels made
        # on the videos to the recording's pixels (io.source_sizes)
        write_source_sizes(out, resize, {
            cam.name: (files[cam.name], (sources[cam.name].width, sources[cam.name].height),
                       (cam.width, cam.height)) for cam in final})
        skipped = {n: p.skipped + (p.remaining() if max_frames else 0)
                   for n, p in placers.items()}
        notes += _timing_notes(placers, files, rate, timing, fps is not None)
    except BaseException:
        shutil.rmtree(out, ignore_errors=True)   # no half-written recording (rerun works)
        raise
    finally:
        for s in sources.values():
            s.close()
    if not stamps:
        shutil.rmtree(out, ignore_errors=True)
        raise ImportVideoError(f'{session}: no frame could be read')
    return dict(cameras=final, files=files, instants=len(stamps), stamps=(stamps[0],
                stamps[-1]), fps=rate, notes=notes, skipped=skipped,
                missing={n: p.missing for n, p in placers.items()},
                dropped={n: p.dropped for n, p in placers.items()},
                counts={n: sources[n].position for n in names})


def run(args):
    from monet_ros.geometry.rig import RigError
    from monet_ros.io import BagWriterError
    from monet_ros.labels import LabelError

    prog = 'monet import videos'
    raw = args.transport == 'raw'
    if raw and args.format is not None:
        print(f'{prog}: --format {args.format} applies to CompressedImage topics, not --raw',
              file=sys.stderr)
        return 2
    try:
        result = import_videos(args.session, args.calibration, args.out, fps=args.fps,
                               offsets=args.offsets, resize=args.resize, raw=raw,
                               fmt=args.format or 'jpeg', quality=args.quality,
                               camera_map=args.camera_map, start_ns=args.start_ns,
                               max_frames=args.max_frames, progress=not args.quiet,
                               timing=args.timing, rig_units=args.rig_units)
    except (ImportVideoError, LabelError, RigError, BagWriterError, ValueError,
            OSError) as error:
        print(f'{prog}: {error}', file=sys.stderr)
        return 2
    for note in result['notes']:
        print(f'{prog}: note: {note}', file=sys.stderr)
    dropped = {n: k for n, k in result['skipped'].items() if k}
    missing = {n: k for n, k in result['missing'].items() if k}
    doubled = {n: k for n, k in result['dropped'].items() if k}
    kind = 'Image rgb8' if raw else f'CompressedImage {args.format or "jpeg"}'
    print(f'{prog}: {len(result["cameras"])} cameras x {result["instants"]} '
          f'instants at {result["fps"]:g} fps ({kind}), stamps {result["stamps"][0]} .. '
          f'{result["stamps"][1]} ns -> {args.out}'
          + (f'; frames not imported (offsets / --max-frames): {dropped}' if dropped else '')
          + (f'; instants without a view (missing frames): {missing}' if missing else '')
          + (f'; frames dropped (a second frame nearest one instant): {doubled}'
             if doubled else ''))
    for cam in result['cameras']:
        print(f'  {cam.name} <- {result["files"][cam.name]} ({cam.width}x{cam.height}, '
              f'{result["counts"][cam.name]} frames read)')
    return 0
