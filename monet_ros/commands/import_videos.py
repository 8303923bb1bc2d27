"""`monet import videos SESSION --calibration CAL --out REC`: per-camera videos (or image
folders) + a calibration -> a rosbag2 MCAP recording that every `monet` command and the
player read.

    monet import videos SESSION_DIR --calibration calibration.toml --out rec
        [--fps 60] [--offsets cam01=3] [--resize 0.5] [--compressed|--raw]
        [--camera-map cam_01=cam01] [--start-ns N]

- SESSION_DIR holds one video per camera (any file OpenCV/FFmpeg decodes: .mp4, .avi,
  .mkv, .mov, ...) or one folder of images per camera (.png/.jpg, sorted by name). A
  camera of the calibration (any monet_ros.geometry.load_rig format) is matched to the
  entry whose name contains the camera name, as anipose does (the longest camera name
  wins, so cam1 does not take cam10's file); --camera-map renames calibration cameras
  first (Pose2Sim's cam_01 -> cam01 for files cam01.mp4). Every camera must match exactly
  one entry (else exit 2 naming the camera and the entries); entries no camera matches
  are listed and ignored.
- Stamps: stamp of video frame j of camera c = start + round((j - offset_c) * 1e9 / fps)
  ns; --offsets cam=N drops camera c's first N frames (its frame N becomes instant 0),
  N < 0 delays it by |N| instants. fps: --fps, else the videos' own rate (they must agree;
  image folders need --fps). Every camera's frame of one instant has the same stamp.
- Topics per camera NAME: /NAME/image_raw/compressed (CompressedImage, --compressed, the
  default; --format jpeg|png, png is lossless) or /NAME/image_raw (Image rgb8, --raw,
  lossless), /NAME/camera_info every frame (K, D, size; frame NAME_optical), and one
  /tf_static (world -> NAME_optical).
- Image size (monet_ros.io.rig_fit.fit_camera): the calibration's size must be the
  video's. When the video is the calibration scaled by s (both axes), K is scaled
  (c' = (c + 0.5) s - 0.5). When it differs by at most 16 px (codec padding: Pose2Sim's
  demo videos are 1080 wide, its calibration says 1088), the video's size is used with K
  unchanged and a note. Any other difference is an error. --resize s scales images and
  calibration together (cv2.INTER_AREA; Camera.crop of the full frame, the same mapping
  as cv2.resize).
- Frames are streamed one instant at a time (memory: one frame per camera); a tqdm
  progress bar shows the instants written. A failed or interrupted import removes its
  output folder, so the same command can be rerun.
"""
from pathlib import Path
import shutil
import sys

import numpy as np

HELP = 'videos (or image folders) + calibration -> a rosbag2 MCAP recording'
VIDEO_SUFFIXES = ('.mp4', '.avi', '.mkv', '.mov', '.mpg', '.mpeg', '.m4v', '.webm', '.wmv',
                  '.mts', '.ts', '.flv')
IMAGE_SUFFIXES = ('.png', '.jpg', '.jpeg', '.bmp', '.tif', '.tiff')
DEFAULT_START_NS = 1_767_225_600_000_000_000          # 2026-01-01T00:00:00Z


class ImportVideoError(ValueError):
    """A session, calibration or option that cannot be imported; the message names it."""


def add_arguments(parser):
    sub = parser.add_subparsers(dest='import_command', metavar='WHAT')
    sub.required = True
    p = sub.add_parser('videos', help=HELP, description=__doc__.split('\n\n')[0])
    p.add_argument('session', help='folder with one video (or image folder) per camera')
    p.add_argument('--calibration', required=True, help='calibration / rig file (any format '
                   'monet_ros.geometry.load_rig reads: anipose/Pose2Sim TOML, rig YAML, ...)')
    p.add_argument('--out', required=True, help='output rosbag2 folder (must not exist)')
    p.add_argument('--fps', type=float, default=None, help='frame rate (default: the videos)')
    p.add_argument('--offsets', action='append', default=[], metavar='CAM=N',
                   help="drop camera CAM's first N frames (negative: delay it); repeatable")
    p.add_argument('--resize', type=float, default=1.0, help='scale images and calibration '
                   '(0 < s <= 1, e.g. 0.5)')
    group = p.add_mutually_exclusive_group()
    group.add_argument('--compressed', dest='raw', action='store_false',
                       help='CompressedImage topics (default)')
    group.add_argument('--raw', dest='raw', action='store_true', help='raw Image rgb8 topics')
    p.add_argument('--format', choices=('jpeg', 'png'), default='jpeg',
                   help='compression of --compressed (png is lossless)')
    p.add_argument('--quality', type=int, default=90, help='JPEG quality 1..100')
    p.add_argument('--camera-map', action='append', default=[], metavar='SRC=DST',
                   help='rename calibration cameras (e.g. cam_01=cam01); repeatable')
    p.add_argument('--start-ns', type=int, default=DEFAULT_START_NS,
                   help='stamp of instant 0 (ns; default 2026-01-01T00:00:00Z)')
    p.add_argument('--max-frames', type=int, default=0, help='import at most N instants')
    p.add_argument('--quiet', action='store_true', help='no progress bar')


class _Source:
    """Frames of one camera: a video (OpenCV) or a folder of images; rgb uint8."""

    def __init__(self, path):
        import cv2
        self.path = Path(path)
        if self.path.is_dir():
            self.files = sorted(f for f in self.path.iterdir()
                                if f.suffix.lower() in IMAGE_SUFFIXES)
            if not self.files:
                raise ImportVideoError(f'{self.path}: no image ({", ".join(IMAGE_SUFFIXES)})')
            first = self._imread(self.files[0])
            self.height, self.width = first.shape[:2]
            self.count, self.fps, self.capture, self.position = len(self.files), None, None, 0
            return
        self.files = None
        self.capture = cv2.VideoCapture(str(self.path))
        if not self.capture.isOpened():
            raise ImportVideoError(f'{self.path}: OpenCV cannot open this video')
        self.width = int(self.capture.get(cv2.CAP_PROP_FRAME_WIDTH))
        self.height = int(self.capture.get(cv2.CAP_PROP_FRAME_HEIGHT))
        self.count = int(self.capture.get(cv2.CAP_PROP_FRAME_COUNT))
        fps = float(self.capture.get(cv2.CAP_PROP_FPS))
        self.fps = fps if np.isfinite(fps) and fps > 0 else None
        self.position = 0

    def _imread(self, path):
        import cv2
        image = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if image is None:
            raise ImportVideoError(f'{path}: cannot read the image')
        return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)

    def read(self):
        """Next frame (H, W, 3) rgb uint8, or None at the end."""
        import cv2
        if self.files is not None:
            if self.position >= len(self.files):
                return None
            image = self._imread(self.files[self.position])
        else:
            ok, image = self.capture.read()
            if not ok:
                return None
            image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
        self.position += 1
        if image.shape[:2] != (self.height, self.width):
            raise ImportVideoError(f'{self.path}: frame {self.position - 1} is '
                                   f'{image.shape[1]}x{image.shape[0]}, the first was '
                                   f'{self.width}x{self.height}')
        return image

    def close(self):
        if self.capture is not None:
            self.capture.release()


def session_entries(session):
    """{name: path} of the videos and image folders in a session folder."""
    session = Path(session)
    if not session.is_dir():
        raise ImportVideoError(f'{session}: not a folder')
    out = {}
    for entry in sorted(session.iterdir()):
        if entry.is_file() and entry.suffix.lower() in VIDEO_SUFFIXES:
            out[entry.name] = entry
        elif entry.is_dir() and any(f.suffix.lower() in IMAGE_SUFFIXES
                                    for f in entry.iterdir()):
            out[entry.name] = entry
    if not out:
        raise ImportVideoError(f'{session}: no video ({", ".join(VIDEO_SUFFIXES)}) or image '
                               'folder')
    return out


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


def import_videos(session, calibration, out, fps=None, offsets=(), resize=1.0, raw=False,
                  fmt='jpeg', quality=90, camera_map=(), start_ns=DEFAULT_START_NS,
                  max_frames=0, progress=True):
    """Write the recording (module docstring). Returns a dict: cameras (Camera list as
    written), files {camera: path}, instants, stamps (first, last), fps, notes, skipped
    {camera: frames dropped by offsets / beyond the shortest camera}."""
    from tqdm import tqdm

    from monet_ros.geometry import load_rig
    from monet_ros.io import BagWriter
    from monet_ros.io.rig_fit import fit_camera
    from monet_ros.labels import match_camera_names, parse_name_map

    if not 0 < resize <= 1:
        raise ImportVideoError(f'--resize must be in (0, 1], got {resize}')
    if fps is not None and not (np.isfinite(fps) and fps > 0):
        raise ImportVideoError(f'--fps must be positive, got {fps}')
    if not 1 <= int(quality) <= 100:
        raise ImportVideoError(f'--quality must be in 1..100, got {quality}')
    if Path(out).exists():
        raise ImportVideoError(f'{out}: output exists; choose a new folder')
    rename = dict(parse_name_map(camera_map, 'camera'))
    cameras = [c.replace(name=rename.get(c.name, c.name), topic=None)
               for c in load_rig(calibration)]
    names = [c.name for c in cameras]
    entries = session_entries(session)
    files = {cam: entries[e] for cam, e in match_camera_names(names, list(entries)).items()}
    shifts = _offsets(offsets, names)
    sources = {n: _Source(files[n]) for n in names}
    notes, final = [], []
    try:
        rates = {n: s.fps for n, s in sources.items() if s.fps}
        if fps is None:
            if len(rates) != len(names):
                raise ImportVideoError('--fps is needed: ' + ', '.join(
                    str(files[n]) for n in names if n not in rates) + ' has no frame rate')
            if max(rates.values()) - min(rates.values()) > 1e-3 * max(rates.values()):
                raise ImportVideoError('the videos disagree on the frame rate ('
                                       + ', '.join(f'{n} {r:g}' for n, r in rates.items())
                                       + '); give --fps')
            fps = float(np.median(list(rates.values())))
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
        skipped = {n: 0 for n in names}
        for n, k in shifts.items():              # drop the first k frames
            for _ in range(max(k, 0)):
                if sources[n].read() is None:
                    break
                skipped[n] += 1
        lengths = {n: max(s.count - max(shifts.get(n, 0), 0), 0) + max(-shifts.get(n, 0), 0)
                   for n, s in sources.items()}
        total = max(lengths.values()) if lengths else 0
        if max_frames:
            total = min(total, int(max_frames))
        period = 1e9 / fps
        stamps = []
        with BagWriter(out) as writer:
            writer.write_tf_static(int(start_ns), final)
            bar = tqdm(total=total or None, desc='monet import videos', unit='instant',
                       disable=not progress, file=sys.stderr)
            t, active = 0, set(names)
            while active and (not max_frames or t < max_frames):
                stamp = int(start_ns) + int(round(t * period))
                wrote = False
                for cam in final:
                    if cam.name not in active or t < -min(shifts.get(cam.name, 0), 0):
                        continue
                    image = sources[cam.name].read()
                    if image is None:
                        active.discard(cam.name)
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
                if not wrote:
                    break
                stamps.append(stamp)
                bar.update(1)
                t += 1
            bar.close()
        if max_frames:
            for n in names:
                while sources[n].read() is not None:
                    skipped[n] += 1
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
                stamps[-1]), fps=fps, notes=notes, skipped=skipped,
                counts={n: sources[n].position for n in names})


def run(args):
    from monet_ros.geometry.rig import RigError
    from monet_ros.io import BagWriterError
    from monet_ros.labels import LabelError

    try:
        result = import_videos(args.session, args.calibration, args.out, fps=args.fps,
                               offsets=args.offsets, resize=args.resize, raw=args.raw,
                               fmt=args.format, quality=args.quality,
                               camera_map=args.camera_map, start_ns=args.start_ns,
                               max_frames=args.max_frames, progress=not args.quiet)
    except (ImportVideoError, LabelError, RigError, BagWriterError, ValueError,
            OSError) as error:
        print(f'monet import videos: {error}', file=sys.stderr)
        return 2
    for note in result['notes']:
        print(f'monet import videos: note: {note}', file=sys.stderr)
    dropped = {n: k for n, k in result['skipped'].items() if k}
    print(f'monet import videos: {len(result["cameras"])} cameras x {result["instants"]} '
          f'instants at {result["fps"]:g} fps, stamps {result["stamps"][0]} .. '
          f'{result["stamps"][1]} ns -> {args.out}'
          + (f'; frames not imported (offsets / --max-frames): {dropped}' if dropped else ''))
    for cam in result['cameras']:
        print(f'  {cam.name} <- {result["files"][cam.name]} ({cam.width}x{cam.height}, '
              f'{result["counts"][cam.name]} frames read)')
    return 0
