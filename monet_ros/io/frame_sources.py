"""Frames of one camera for `monet import videos`, each with the instant it belongs to
(no ROS): a video (OpenCV / FFmpeg) or a folder of images.

Which instant a frame is (before the camera's --offsets):
- image folder: the number in the file name, the last run of digits of its stem
  ('frame_0004.png' -> 4, 'cam1_img0042.jpg' -> 42), minus the smallest number of every
  image folder of the session (so 0000... and 0001... both start at instant 0). A file
  that is not there is a missing view at its instant, not a shift of the later ones. When
  a folder's names carry no number (or not all do) its frames are taken in name order
  (instant = position) and the source says so (`order_note`).
- video: the frame's container (presentation) time, OpenCV's CAP_PROP_POS_MSEC (FFmpeg's
  best-effort pts from the stream start): instant = round(time * fps). For a constant
  frame rate video at `fps` this is the frame index; for a variable frame rate (VFR)
  video each frame lands on the instant nearest its time (at most half a period off), an
  instant no frame is nearest is a missing view and a second frame nearest one instant is
  dropped (both counted by the importer). timing='index' (or a video without usable
  container times) uses the frame index instead.
"""
from pathlib import Path
import re

import numpy as np

VIDEO_SUFFIXES = ('.mp4', '.avi', '.mkv', '.mov', '.mpg', '.mpeg', '.m4v', '.webm', '.wmv',
                  '.mts', '.ts', '.flv')
IMAGE_SUFFIXES = ('.png', '.jpg', '.jpeg', '.bmp', '.tif', '.tiff')
# frame intervals whose longest exceeds the shortest by more than this fraction: VFR
VFR_SPREAD = 0.1
_DIGITS = re.compile(r'(\d+)(?!.*\d)')


class FrameSourceError(ValueError):
    """A video or image folder that cannot be read; the message names the file."""


def frame_number(path):
    """The number in a file name (the last run of digits of its stem) or None."""
    match = _DIGITS.search(Path(path).stem)
    return int(match.group(1)) if match else None


_JPEG_SUFFIXES = ('.jpg', '.jpeg')
_JPEG_END = b'\xff\xd9'


def _imread(path):
    """rgb uint8 (H, W, 3) of an image file; FrameSourceError naming it when it cannot be
    read or is a truncated JPEG (no end-of-image marker: OpenCV decodes what is there and
    fills the rest with grey, with only a libjpeg warning on stderr)."""
    import cv2
    path = Path(path)
    if path.suffix.lower() in _JPEG_SUFFIXES:
        try:
            with open(path, 'rb') as stream:
                stream.seek(max(0, path.stat().st_size - 4096))
                tail = stream.read().rstrip(b'\x00\r\n\t ')
        except OSError as error:
            raise FrameSourceError(f'{path}: cannot read the image ({error.strerror})') from None
        if not tail.endswith(_JPEG_END):
            raise FrameSourceError(f'{path}: truncated JPEG (no end-of-image marker)')
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise FrameSourceError(f'{path}: cannot read the image')
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


class FrameSource:
    """Frames of one camera, rgb uint8 (H, W, 3), in order, each with its frame key.

    Attributes: path, width, height, count (frames; a video's is the container's
    estimate), fps (a video's nominal rate, None for images), kind ('video' / 'images'),
    numbered (image folder whose names all carry a distinct number), position (frames
    read). Raises FrameSourceError naming the file; with skip_unreadable an image file that
    cannot be read (or a truncated JPEG) is instead a frame whose image is None, its reason
    appended to `unreadable` (the size comes from the first readable image)."""

    def __init__(self, path, skip_unreadable=False):
        import cv2
        self.path = Path(path)
        self.skip_unreadable, self.unreadable = skip_unreadable, []
        self.position, self.capture, self.order_note = 0, None, None
        self._last_ms, self.intervals_ms, self.times_ok = None, [np.inf, 0.0], True
        if self.path.is_dir():
            self.kind = 'images'
            files = sorted(f for f in self.path.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES)
            if not files:
                videos = _videos_in(self.path)
                if len(videos) > 1:
                    raise FrameSourceError(
                        f'{self.path}: {len(videos)} videos ({", ".join(v.name for v in videos)})'
                        ': a camera folder holds one video (or its images)')
                raise FrameSourceError(f'{self.path}: no image ({", ".join(IMAGE_SUFFIXES)})')
            numbers = [frame_number(f) for f in files]
            self.numbered = all(n is not None for n in numbers)
            if self.numbered:
                seen = {}
                for f, n in zip(files, numbers):
                    if n in seen:
                        raise FrameSourceError(f'{f}: frame number {n} is also {seen[n].name}')
                    seen[n] = f
                order = np.argsort(numbers, kind='stable')
                self.files = [files[i] for i in order]
                self.numbers = [numbers[i] for i in order]
            else:
                self.files, self.numbers = files, list(range(len(files)))
                self.order_note = (f'{self.path}: file names carry no frame number: frames '
                                   'taken in name order (a missing file would shift the rest)')
            first = failure = None
            for file in self.files if skip_unreadable else self.files[:1]:
                try:
                    first = _imread(file)
                    break
                except FrameSourceError as error:
                    if not skip_unreadable:
                        raise
                    failure = error
            if first is None:
                raise FrameSourceError(f'{self.path}: no image is readable ({failure})')
            self.height, self.width = first.shape[:2]
            self.count, self.fps = len(self.files), None
            return
        self.kind, self.files, self.numbered = 'video', None, False
        self.capture = cv2.VideoCapture(str(self.path))
        if not self.capture.isOpened():
            raise FrameSourceError(f'{self.path}: OpenCV cannot open this video')
        self.width = int(self.capture.get(cv2.CAP_PROP_FRAME_WIDTH))
        self.height = int(self.capture.get(cv2.CAP_PROP_FRAME_HEIGHT))
        self.count = int(self.capture.get(cv2.CAP_PROP_FRAME_COUNT))
        fps = float(self.capture.get(cv2.CAP_PROP_FPS))
        self.fps = fps if np.isfinite(fps) and fps > 0 else None

    @property
    def first_number(self):
        """The smallest frame number of a numbered image folder, else None."""
        return self.numbers[0] if self.kind == 'images' and self.numbered else None

    @property
    def variable_rate(self):
        """True when the container times read so far are not evenly spaced (VFR)."""
        low, high = self.intervals_ms
        return self.times_ok and np.isfinite(low) and high > low * (1.0 + VFR_SPREAD)

    def read(self):
        """Next (frame key, image) or None at the end. key: the image's file number, or a
        video frame's container time in ms (its index when the video has no increasing
        container times: `times_ok` false)."""
        import cv2
        if self.files is not None:
            if self.position >= len(self.files):
                return None
            key = self.numbers[self.position]
            try:
                image = _imread(self.files[self.position])
            except FrameSourceError as error:
                if not self.skip_unreadable:
                    raise
                self.unreadable.append(str(error))
                self.position += 1
                return key, None
        else:
            ok, image = self.capture.read()
            if not ok:
                return None
            image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
            key = float(self.capture.get(cv2.CAP_PROP_POS_MSEC))
            if self._last_ms is not None and self.times_ok:
                step = key - self._last_ms
                if (not np.isfinite(step) or step <= 0) and self.position >= 2:
                    raise FrameSourceError(
                        f'{self.path}: frame {self.position}: container time {key:g} ms does '
                        f'not follow {self._last_ms:g} ms; give --timing index')
                if not np.isfinite(step) or step <= 0:
                    self.times_ok = False         # no container times at all: by index
                else:
                    self.intervals_ms = [min(self.intervals_ms[0], step),
                                         max(self.intervals_ms[1], step)]
            self._last_ms = key
        self.position += 1
        if image.shape[:2] != (self.height, self.width):
            raise FrameSourceError(f'{self.path}: frame {self.position - 1} is '
                                   f'{image.shape[1]}x{image.shape[0]}, the first was '
                                   f'{self.width}x{self.height}')
        return key, image

    def close(self):
        if self.capture is not None:
            self.capture.release()


def _videos_in(folder):
    """The video files directly inside a folder, sorted by name."""
    return sorted(f for f in folder.iterdir() if f.is_file()
                  and f.suffix.lower() in VIDEO_SUFFIXES)


def session_entries(session):
    """{name: path} of the cameras' sources in a session folder: a video file (name = its
    file name), a folder of images (name = the folder's), or a folder holding its camera's
    video (sleap-anipose's layout <session>/<camera>/<video>.mp4: name = the folder's,
    path = the video; its subfolders, e.g. calibration_images/, are not looked into). A
    folder holding several videos is an entry too: FrameSource names them if a camera is
    matched to it. Raises FrameSourceError when there is none."""
    session = Path(session)
    if not session.is_dir():
        raise FrameSourceError(f'{session}: not a folder')
    out = {}
    for entry in sorted(session.iterdir()):
        if entry.is_file() and entry.suffix.lower() in VIDEO_SUFFIXES:
            out[entry.name] = entry
        elif entry.is_dir() and any(f.suffix.lower() in IMAGE_SUFFIXES
                                    for f in entry.iterdir()):
            out[entry.name] = entry
        elif entry.is_dir() and _videos_in(entry):
            videos = _videos_in(entry)
            out[entry.name] = videos[0] if len(videos) == 1 else entry
    if not out:
        raise FrameSourceError(f'{session}: no video ({", ".join(VIDEO_SUFFIXES)}), image '
                               'folder or folder holding one video per camera')
    return out
