"""Fit a calibration file's cameras to a recording (no ROS): names mapped (cam_01 ->
cam01), image topics found, and the calibration's image size fitted to the recording's
images - the lab's full-resolution calibration used with a half-resolution recording.

fit_camera(cam, width, height, source): the camera for width x height images:
- the same size: unchanged;
- a scale s of the calibration's size (s from the height, else the width), within 16 px
  of the scaled size in each axis (codec padding / cropping, e.g. Pose2Sim's 1080-wide
  videos with a 1088-wide calibration): K scaled exactly as cv2.resize maps pixels
  (Camera.crop of the full frame: c' = (c + 0.5) s - 0.5; s = 1 keeps K), the image's
  size taken, and a note saying so;
- anything else: RigFitError naming the source, the camera and both sizes.
"""
from .images import any_image_to_numpy
from .reader import BagError

SIZE_SLACK_PX = 16


class RigFitError(BagError):
    """A calibration camera that does not fit the recording; the message names it."""


def fit_camera(cam, width, height, source):
    """(Camera for width x height images, note or '') - module docstring."""
    if (cam.width, cam.height) == (width, height):
        return cam, ''
    for scale in (height / cam.height, width / cam.width):
        w, h = cam.width * scale, cam.height * scale
        slack = max(1.0, SIZE_SLACK_PX * scale)
        if abs(w - width) > slack or abs(h - height) > slack:
            continue
        fitted = cam if abs(scale - 1) < 1e-12 else cam.crop((0, 0, cam.width, cam.height),
                                                              (w, h))
        fitted = fitted.replace(width=width, height=height)
        exact = abs(w - width) <= 1.0 and abs(h - height) <= 1.0
        what = (f'K scaled by {scale:.6g}' if abs(scale - 1) >= 1e-12 else 'K kept as '
                'calibrated') + ('' if exact else ' (the size differs by a few pixels: codec '
                                 'padding?); image size taken from the images')
        return fitted, (f'{cam.name}: calibration {cam.width}x{cam.height}, {source} is '
                        f'{width}x{height}: {what}')
    raise RigFitError(f'{source}: image {width}x{height} does not fit camera {cam.name} of the '
                      f'calibration ({cam.width}x{cam.height}); not a scale of it within '
                      f'{SIZE_SLACK_PX} px')


def fit_rig_to_bag(cameras, reader, camera_map=()):
    """(cameras fitted to the bag, notes): each calibration camera renamed by camera_map
    ((source, target) pairs), given the bag's image topic of that name (its own topic when
    the bag has it, else /NAME/image_raw or /NAME/image_raw/compressed) and fitted to the
    size of its first image. Raises RigFitError naming a camera without images."""
    from .rig import _image_topic

    rename = dict(camera_map)
    out, notes = [], []
    for cam in cameras:
        name = rename.get(cam.name, cam.name)
        topic = cam.topic if cam.topic in reader.topics else _image_topic(reader, name)
        if topic is None:
            images = sorted(t for t, i in reader.topics.items()
                            if i.msgtype.endswith(('/Image', '/CompressedImage')))
            raise RigFitError(f'{reader.path}: no image topic for calibration camera '
                              f'{cam.name!r}' + (f' (renamed {name!r})' if name != cam.name
                                                 else '')
                              + f'; image topics: {", ".join(images) or "none"}; rename with '
                              f'--camera-map {cam.name}=NAME')
        first = next(iter(reader.messages(topics=[topic])), None)
        if first is None:
            raise RigFitError(f'{reader.path}: topic {topic} of camera {name} has no message')
        try:
            height, width = any_image_to_numpy(first.msg).shape[:2]
        except Exception as exc:    # noqa: BLE001 - any decode failure is named here
            raise RigFitError(f'{reader.path}: first image on {topic} does not decode '
                              f'({exc})') from None
        fitted, note = fit_camera(cam.replace(name=name, topic=topic), width, height, topic)
        out.append(fitted)
        if note:
            notes.append(note)
    return out, notes
