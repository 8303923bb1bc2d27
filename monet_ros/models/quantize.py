"""INT8 inference: ONNX Runtime static quantisation of a detector network (`precision int8`).

The float32 ONNX export (models.onnx_backend) is quantised with
onnxruntime.quantization.quantize_static: QDQ format, weights int8 per output channel,
activations uint8 per tensor (U8S8, the layout ONNX Runtime's x86 int8 kernels take), MinMax
calibration on network-input crops.

The calibration rule: a quant is calibrated on the crops the run will make, because the
activation ranges follow the crops (bench/results/int8_accuracy.md: a quant calibrated on
full-frame crops and run on tracked crops, where the subject fills the crop, lands 12 px
from float32 on real video; calibrated on tracked crops, within 1 px). Its `crops` key
names which: 'full' (full-frame crops, grown to the input's aspect: `--no-track`, the
detector node with track false, Detector.predict without boxes; calibration_crops reads
them from a recording), 'box-<x0>_<y0>_<x1>_<y1>' (one fixed box: the detector node with
track false and a `box`; calibration_crops with that box) or a tracked key
'tracked-m<margin>-t<trim>-k<min_points>' (the crops the tracked rule of
monet_ros.crop_rule makes around the subject, with those settings; made above this layer by
monet_ros.int8_calibration, which runs the float32 network with the rule over the
recording, and given here as crops or a function that makes them). The quantised network is
cached beside the checkpoint as `<checkpoint stem>.<sha256[:16]>.<crops key>.int8.onnx`
(int8_path_for), written atomically; the name is keyed by the checkpoint's sha256 and the
crops key, so new weights need a new calibration, a quant never belongs to other weights,
and a tracked and a full-frame quant of one checkpoint sit side by side, neither used for
the other. The name alone proves nothing (a file copied or renamed onto it would be used
for weights it was not made from): every quant written records, in its ONNX metadata_props,
the full sha256 of its checkpoint and its crops key (RECORD_KEYS), and a cached or given
quant is used only when its record says it is this checkpoint's, of these crops
(check_record); one that says otherwise, or records nothing (made before the record, or not
here), is calibrated again where calibration data is given, else refused in one line. Quants
cached before the crops key (`<stem>.<sha256[:16]>.int8.onnx`, full-frame calibrated) are
no longer read.

CPU rule (cpu_int8_feature): int8 is refused, not only warned about, on a CPU without
AVX512-VNNI, AVX-VNNI or AMX-INT8. Without them ONNX Runtime's uint8 x int8 convolutions run
on AVX2's vpmaddubsw, whose 16-bit pair sums saturate (u8 255 x s8 127 x 2 > 32767): the
heatmaps come out wrong in a data-dependent way, not merely slower, and the speed-up over
float32 is small there. `precision auto` then keeps float32 (resolve_precision).
"""
import logging
from pathlib import Path
import re
import tempfile

import numpy as np

from monet_ros.atomic import atomic_write, sha256_file
from monet_ros.models.onnx_backend import import_deferred

# CPU flags (/proc/cpuinfo) of the int8 dot-product instructions, and their names
INT8_FLAGS = (('amx_int8', 'AMX-INT8'), ('avx512_vnni', 'AVX512-VNNI'), ('avx_vnni', 'AVX-VNNI'))
CALIBRATION_IMAGES = 64     # crops a recording gives for calibration (at most)
INT8_SUFFIX = '.int8.onnx'
FULL_CROPS = 'full'          # the crops key of full-frame calibration
# crops keys (int8_calibration.crops_key): 'full', 'tracked-m<margin>-t<trim>-k<min_points>',
# 'box-<x0>_<y0>_<x1>_<y1>' (a fixed box) or
# 'subjects<N>-d<tiles>-m<margin>-t<trim>-k<min_points>' (several subjects)
_NUMBER = r'-?[0-9.]+(?:e[+-][0-9]+)?'
CROPS_KEY = re.compile(rf'full|(?:tracked|subjects[0-9]+-d[0-9]+)-m{_NUMBER}-t{_NUMBER}-'
                       rf'k[0-9]+|box-{_NUMBER}_{_NUMBER}_{_NUMBER}_{_NUMBER}')


# the metadata_props keys of a quant's record: the checkpoint's full sha256, the crops key
RECORD_KEYS = ('monet_ros.checkpoint_sha256', 'monet_ros.int8_crops')


class Int8Error(ValueError):
    """int8 cannot run here (CPU, backend, no calibration data or cached quant); the message
    is one line naming the cause (a ValueError: commands exit 2, nodes refuse to start)."""


def cpu_flags(path='/proc/cpuinfo'):
    """The set of CPU feature flags of the first processor in `path` (empty when the file
    cannot be read: not Linux)."""
    try:
        with open(path) as stream:
            for line in stream:
                if line.startswith('flags'):
                    return set(line.partition(':')[2].split())
    except OSError:
        pass
    return set()


def cpu_int8_feature(flags=None):
    """What makes int8 fast and exact on this CPU, as text ('AMX-INT8 and AVX512-VNNI', ...),
    or None where ONNX Runtime would fall back to AVX2's saturating vpmaddubsw (see the module
    docstring). flags: a set of /proc/cpuinfo flags (None = read them)."""
    flags = cpu_flags() if flags is None else set(flags)
    found = [text for flag, text in INT8_FLAGS if flag in flags]
    return ' and '.join(found) or None


def check_int8_cpu():
    """Raises Int8Error unless cpu_int8_feature finds VNNI or AMX-INT8."""
    if cpu_int8_feature() is None:
        raise Int8Error('precision int8 needs a CPU with AVX512-VNNI, AVX-VNNI or AMX-INT8 '
                        '(/proc/cpuinfo flags avx512_vnni, avx_vnni, amx_int8); without them '
                        "ONNX Runtime's int8 convolutions saturate (wrong heatmaps); use "
                        'float32 (precision auto picks it there)')


def check_crops_key(crops):
    """`crops` (a crops key, see the module docstring) or ValueError naming it."""
    if not isinstance(crops, str) or not CROPS_KEY.fullmatch(crops):
        raise ValueError(f"int8 crops key must be 'full', 'tracked-m<margin>-t<trim>-"
                         f"k<min_points>', 'box-<x0>_<y0>_<x1>_<y1>' or 'subjects<N>-"
                         f"d<tiles>-m<margin>-t<trim>-k<min_points>', got {crops!r}")
    return crops


def int8_path_for(checkpoint, sha256, crops=FULL_CROPS):
    """Where the int8 quant of a checkpoint with this sha256, calibrated on the crops
    `crops` names (a crops key: 'full', a tracked or a box key), is cached (beside it):
    `<stem>.<sha256[:16]>.<crops>.int8.onnx`."""
    checkpoint = Path(checkpoint)
    return checkpoint.with_name(f'{checkpoint.stem}.{sha256[:16]}.{check_crops_key(crops)}'
                                f'{INT8_SUFFIX}')


def with_record(data, sha256, crops):
    """The quant's ONNX bytes `data` with its record (RECORD_KEYS in metadata_props): the
    full sha256 of the checkpoint it was made from and the crops key it was calibrated on."""
    onnx = import_deferred('onnx')

    model = onnx.load_from_string(data)
    for key, value in zip(RECORD_KEYS, (sha256, crops)):
        entry = model.metadata_props.add()
        entry.key, entry.value = key, value
    return model.SerializeToString()


def check_record(path, sha256, crops, what='calibration'):
    """Int8Error (one line naming `what` and the file) unless the quant at `path` records
    (with_record) the checkpoint sha256 `sha256` (full) and the crops key `crops`: a file
    that is not ONNX, one without a record, or one of other weights or crops."""
    onnx = import_deferred('onnx')

    try:
        model = onnx.load(str(path), load_external_data=False)
    except Exception as error:  # noqa: BLE001 - protobuf / onnx raise many kinds
        raise Int8Error(f'{what} {path}: not a readable ONNX quant ({type(error).__name__})'
                        ) from None
    record = {p.key: p.value for p in model.metadata_props}
    made, on = record.get(RECORD_KEYS[0]), record.get(RECORD_KEYS[1])
    if made is None or on is None:
        raise Int8Error(f'{what} {path}: the quant records no checkpoint (made before quants '
                        'recorded theirs, or not by monet_ros): give calibration data to '
                        'calibrate again, or delete it')
    if made != sha256 or on != crops:
        raise Int8Error(f'{what} {path}: the quant was made from a checkpoint of sha256 '
                        f'{made[:16]} on crops {on}, not this one ({sha256[:16]}, crops '
                        f'{crops}), whatever its name: give calibration data to calibrate '
                        'again, or delete it')


def cached_int8(checkpoint, sha256=None, crops=FULL_CROPS):
    """The cached int8 quant of `checkpoint` (Path) calibrated on `crops` (a crops key)
    when it exists, else None."""
    if checkpoint is None or not Path(checkpoint).is_file():
        return None
    path = int8_path_for(checkpoint, sha256 or sha256_file(checkpoint), crops)
    return path if path.is_file() else None


def crops_to_input(crops):
    """(N, H, W, 3) uint8 RGB crops -> (N, 3, H, W) float32 in [0, 1]: the network input, as
    Detector.forward makes it."""
    crops = np.asarray(crops)
    if crops.ndim != 4 or crops.shape[-1] != 3 or crops.dtype != np.uint8:
        raise ValueError(f'calibration crops must be (N, H, W, 3) uint8 RGB, got '
                         f'{crops.shape} {crops.dtype}')
    return np.ascontiguousarray(crops.transpose(0, 3, 1, 2), dtype=np.float32) / 255.0


def calibration_crops(recording, input_size, count=CALIBRATION_IMAGES, box=None):
    """Up to `count` network-input crops (N, H, W, 3) uint8 RGB of a recording's frames.

    The calibration set of crops key 'full' (full-frame runs: `--no-track`, track false)
    or, with `box` (x0, y0, x1, y1) pixel edges, of that fixed box's key.
    recording: a rosbag2 folder or .mcap; input_size: (H, W) of the network. Every
    Image / CompressedImage topic is read; frames are taken evenly over the recording (each
    topic's first frame, then every k-th message) and cropped full frame (or to `box`),
    grown to the input's aspect (models.crop), as such a run crops them. Raises Int8Error
    when the recording cannot be read or has no image that decodes."""
    from monet_ros.io import any_image_to_numpy, open_bag
    from monet_ros.io.images import to_rgb8
    from monet_ros.models.crop import crop_images, fit_boxes_to_aspect, full_frame_boxes

    h, w = (int(v) for v in input_size)
    try:
        reader = open_bag(recording)
        topics = reader.topics_of_type('sensor_msgs/msg/Image', 'sensor_msgs/msg/CompressedImage')
        total = sum(int(getattr(reader.topics[t], 'count', 0) or 0) for t in topics)
    except (OSError, ValueError) as error:
        raise Int8Error(f'calibration {recording}: cannot read it ({error})') from None
    if not topics:
        raise Int8Error(f'calibration {recording}: no Image or CompressedImage topic')
    every = max(1, total // count) if total else 1
    crops = []
    try:
        for n, message in enumerate(reader.messages(topics=topics)):
            if n % every:
                continue
            try:
                image = to_rgb8(any_image_to_numpy(message.msg))
            except ValueError:
                continue              # a view that does not decode: not calibration data
            crop = (full_frame_boxes([(image.shape[1], image.shape[0])], w / h) if box is None
                    else fit_boxes_to_aspect(np.asarray([box], np.float64), w / h))
            crops.append(crop_images([image], crop, (w, h))[0])
            if len(crops) >= count:
                break
    except (OSError, ValueError) as error:
        raise Int8Error(f'calibration {recording}: cannot read it ({error})') from None
    if not crops:
        raise Int8Error(f'calibration {recording}: no image decodes')
    return np.stack(crops)


def _reader(inputs, batch=8):
    CalibrationDataReader = import_deferred('onnxruntime.quantization').CalibrationDataReader

    class Batches(CalibrationDataReader):
        def __init__(self):
            self.batches = iter([{'images': inputs[i:i + batch]}
                                 for i in range(0, len(inputs), batch)])

        def get_next(self):
            return next(self.batches, None)

    return Batches()


def quantize_onnx(float_onnx, crops):
    """The int8 (QDQ, per-channel weights) ONNX bytes of a float32 export (bytes or path),
    calibrated (MinMax) on `crops` (N, H, W, 3) uint8 RGB. Raises Int8Error when ONNX Runtime's
    quantiser is missing or fails."""
    try:
        quantization = import_deferred('onnxruntime.quantization')
    except ImportError:
        raise Int8Error('precision int8 needs the onnxruntime package (pip install -r '
                        'requirements.txt)') from None
    inputs = crops_to_input(crops)
    if not len(inputs):
        raise Int8Error('precision int8: no calibration crops')
    with tempfile.TemporaryDirectory(prefix='monet-int8-') as folder:
        source = Path(folder) / 'float.onnx'
        target = Path(folder) / 'int8.onnx'
        source.write_bytes(float_onnx if isinstance(float_onnx, bytes)
                           else Path(float_onnx).read_bytes())
        # the quantiser logs advice (pre-processing) to the root logger: not the user's
        logging.disable(logging.WARNING)
        try:
            q = quantization
            q.quantize_static(str(source), str(target), _reader(inputs),
                              quant_format=q.QuantFormat.QDQ, per_channel=True,
                              activation_type=q.QuantType.QUInt8,
                              weight_type=q.QuantType.QInt8,
                              calibrate_method=q.CalibrationMethod.MinMax)
        except Exception as error:  # noqa: BLE001 - the quantiser raises many kinds
            raise Int8Error(f'int8 quantisation failed ({type(error).__name__}: '
                            f'{error})') from None
        finally:
            logging.disable(logging.NOTSET)
        return target.read_bytes()


def check_recording(recording):
    """`recording` (a rosbag2 folder or .mcap holding an Image or CompressedImage topic:
    calibration data) or Int8Error, one line naming it (parameter / option calibration):
    it does not exist, is not a recording (a file without the MCAP magic, a folder without
    .mcap files) or has no image topic. Reads the magic, metadata.yaml and the files'
    summaries, no message."""
    from monet_ros.io import open_bag
    from monet_ros.io.mcap_scan import MAGIC

    path = Path(recording)
    where = (f'calibration {recording}: neither a recording (rosbag2 folder or .mcap) nor a '
             f'quant (*{INT8_SUFFIX})')
    if not path.exists():
        raise Int8Error(f'calibration {recording}: no such file or folder (a recording: '
                        f'rosbag2 folder or .mcap, or a quant *{INT8_SUFFIX})')
    try:
        if path.is_file():
            with open(path, 'rb') as stream:
                if stream.read(len(MAGIC)) != MAGIC:
                    raise Int8Error(f'{where}: no MCAP magic at its start')
        topics = open_bag(path).topics_of_type('sensor_msgs/msg/Image',
                                               'sensor_msgs/msg/CompressedImage')
    except (OSError, ValueError) as error:
        if isinstance(error, Int8Error):
            raise
        raise Int8Error(f'{where} ({error})') from None
    if not topics:
        raise Int8Error(f'calibration {recording}: a recording without an Image or '
                        'CompressedImage topic (nothing to calibrate on)')
    return recording


def check_calibration(calibration, crops=FULL_CROPS, checkpoint=None, sha256=None):
    """Check int8_onnx_for's `calibration` for a run with crops key `crops` before any
    cached quant is looked up, so it is refused the same whether or not one is cached.
    Returns the quant (Path) when it is one, else None. Raises Int8Error (one line naming
    calibration and the file): a quant (`*.int8.onnx`) of other crops, of other weights
    than `checkpoint` (sha256: its sha256, None = read it) or missing; a recording (str /
    Path, or a function with a `recording` attribute: int8_calibration's) that
    check_recording refuses; a recording given as a path for crops other than 'full'."""
    if isinstance(calibration, (str, Path)) and str(calibration).endswith(INT8_SUFFIX):
        given = Path(calibration)
        if not given.name.endswith(f'.{crops}{INT8_SUFFIX}'):
            raise Int8Error(f'calibration {given}: a quant calibrated on other crops than '
                            f"this run's ({crops}: the quant must be named *.{crops}"
                            f'{INT8_SUFFIX}; give the recording to calibrate on instead)')
        if checkpoint is not None:
            sha256 = sha256 or sha256_file(checkpoint)
            if not given.name.endswith(f'.{sha256[:16]}.{crops}{INT8_SUFFIX}'):
                mine = int8_path_for(checkpoint, sha256, crops)
                raise Int8Error(f'calibration {given}: a quant of other weights (this '
                                f'checkpoint is {Path(checkpoint).name}, sha256 '
                                f'{sha256[:16]}: {mine.name})')
        if not given.is_file():
            raise Int8Error(f'calibration {given}: no such quant')
        if checkpoint is not None:
            check_record(given, sha256, crops)
        return given
    if isinstance(calibration, (str, Path)) and str(calibration):
        if crops != FULL_CROPS:
            raise Int8Error(f'calibration {calibration}: int8 with crops {crops} calibrates '
                            'on the crops the run makes, not on full frames of a recording '
                            'read here (monet_ros.int8_calibration makes them)')
        check_recording(calibration)
    elif callable(calibration) and getattr(calibration, 'recording', None) is not None:
        check_recording(calibration.recording)
    return None


def int8_onnx_for(model, checkpoint=None, calibration=None, sha256=None, crops=FULL_CROPS):
    """(the int8 network of `model` (eval mode, CPU) as a path (cached) or ONNX bytes, the
    one line saying which quant: calibrated on what and written where, or the cached or
    given quant used).

    crops: the crops key of the run (the module docstring's calibration rule): 'full' or a
    tracked key; it names the cached quant, and the calibration data must be of those
    crops. checkpoint: the file `model` was loaded from (the quant is cached beside it,
    keyed by its sha256 and `crops`), or None (quantised in memory, never cached).
    calibration: None (the cached quant must exist), a recording (rosbag2 folder or .mcap:
    with crops 'full' calibration_crops; other keys need the crops of their rule,
    monet_ros.int8_calibration), a cached quant (`*.<crops>.int8.onnx`, which must
    be this checkpoint's and of these crops), crops (N, H, W, 3) uint8, or a function of no
    argument returning such crops (called only when no cached quant exists; with a
    `recording` attribute, the recording it reads, named in the note and checked).
    `calibration` is checked first (check_calibration), cached quant or not; then a cached
    quant is used as it is (calibration is not read). Where the folder is not writable the
    quant is used from memory. Raises Int8Error (one line) when there is no calibration
    data and no cached quant, or check_calibration refuses it."""
    from monet_ros.models.onnx_backend import export_onnx

    check_crops_key(crops)
    path = None
    if checkpoint is not None:
        sha256 = sha256 or sha256_file(checkpoint)
        path = int8_path_for(checkpoint, sha256, crops)
    given = check_calibration(calibration, crops, checkpoint, sha256)
    no_data = calibration is None or (isinstance(calibration, str) and not calibration)
    stale = ''
    if path is not None and path.is_file():
        try:
            if given is None or given.resolve() != path.resolve():   # else checked above
                check_record(path, sha256, crops, what='cached quant')
            return path, (f'precision int8: cached quant {path} (crops {crops}; not '
                          'calibrating)')
        except Int8Error:
            if no_data and given is None:
                raise
            stale = f'; the cached {path.name} was not made from this checkpoint'
    if given is not None:
        return given, f'precision int8: the given quant {given} (crops {crops})'
    if no_data:
        where = f' and no cached quant {path}' if path is not None else ''
        raise Int8Error(f'precision int8 needs calibration data (a recording or a cached '
                        f'quant: parameter calibration){where}')
    source = ''
    if isinstance(calibration, (str, Path)):
        source = f' of {calibration}'
        crops_data = calibration_crops(calibration, model.input_size)
    elif callable(calibration):
        recording = getattr(calibration, 'recording', None)
        source = f' of {recording}' if recording is not None else ''
        crops_data = np.asarray(calibration())
    else:
        crops_data = np.asarray(calibration)
    data = quantize_onnx(export_onnx(model), crops_data)
    said = f'precision int8: calibrated on {len(crops_data)} crops ({crops}){source}{stale}'
    if path is None:
        return data, f'{said}; kept in memory (no checkpoint to cache it beside)'
    data = with_record(data, sha256, crops)
    try:
        with atomic_write(path) as stream:
            stream.write(data)
    except OSError:
        return data, f'{said}; kept in memory ({path.parent} is not writable)'
    return path, f'{said}; wrote {path}'
