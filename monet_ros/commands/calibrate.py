"""`monet calibrate INPUT... --board BOARD --out calibration.toml`: a rig's calibration from
ChArUco or checkerboard images / videos.

    monet calibrate back/ mid/ side/ top/ --board board.toml --out calibration.toml
        [--distortion k1|k1k2|full] [--fix-principal-point] [--intrinsics CAL]
        [--timestamps times.csv [--tolerance S]] [--format anipose|rig|both]
        [--report report.png | --no-report] [--names a,b,c]

- INPUT: one video (any file OpenCV decodes) or image folder per camera (images in the
  order of the number in their names, as `monet import videos` reads them; frame k of a
  camera is its k-th image).
  Camera names: --names, else the names of an --intrinsics calibration matched to the
  inputs as `monet import videos` does (the input whose name contains the camera name),
  else the folder / file names (a parent folder's when they repeat, e.g.
  back/calibration_images; a prefix / suffix they all share at a separator is dropped).
- Frames are paired across cameras by index (equal frame counts needed), or by time with
  --timestamps CSV (camera,frame,time_s; nearest frame within --tolerance s, default half
  a frame interval of the first camera).
- BOARD: an anipose / sleap-anipose board TOML (monet_ros.calibration.board), or the same
  fields as options (--board-x 8 --board-y 11 --square-length 24 --marker-length 18.75
  --marker-bits 4 --dict-size 1000 [--board-type charuco|checkerboard]).
- Steps (monet_ros.calibration): detect corners (tqdm progress; every frame without a
  board is counted, a board seen only mirrored and an unreadable image (named) apart; when a
  camera finds no board, markers that do not fit the board spec are named with the fields
  to check), per-camera intrinsics, spanning-tree extrinsics, one joint bundle
  adjustment with a robust loss. Translations are in the board's unit: --rig-units names
  it (m, cm, mm), else the rule of monet_ros.geometry.units picks it from the camera
  spread (noted); the outputs state it (rig YAML `units`, TOML [metadata] units).
- Fewer than 2 cameras calibrated: exit 2, with why for each camera left out.
- Output: --out as anipose calibration.toml (--format anipose, the default), the project
  rig YAML (--format rig) or both (--format both: --out and --out with .yaml); a summary
  per camera and pair, the board's geometry triangulated back, loud warnings, and a PNG
  report (default: OUT's name + _report.png).
"""
import os
from pathlib import Path
import sys

HELP = 'calibrate a rig from ChArUco / checkerboard images or videos -> calibration.toml'
FORMATS = ('anipose', 'rig', 'both')
BOARD_OPTIONS = ('board_type', 'board_x', 'board_y', 'square_length', 'marker_length',
                 'marker_bits', 'dict_size')


def add_arguments(parser):
    from monet_ros.calibration.bundle import LOSSES
    from monet_ros.calibration.intrinsics import DISTORTION_MODELS
    from monet_ros.calibration.rig import CalibrationConfig

    defaults = CalibrationConfig()
    parser.add_argument('inputs', nargs='+', metavar='INPUT',
                        help='one video or image folder per camera')
    parser.add_argument('--board', help='board TOML (anipose / sleap-anipose form)')
    parser.add_argument('--board-type', choices=('charuco', 'checkerboard'), default=None)
    parser.add_argument('--board-x', type=int, help='squares (ChArUco) / inner corners '
                        '(checkerboard) along x')
    parser.add_argument('--board-y', type=int, help='... along y')
    parser.add_argument('--square-length', type=float, help='square side (board unit)')
    parser.add_argument('--marker-length', type=float, help='ChArUco marker side')
    parser.add_argument('--marker-bits', type=int, help='ChArUco marker bits (4..7)')
    parser.add_argument('--dict-size', type=int, help='ChArUco dictionary size')
    parser.add_argument('--out', required=True, help='output calibration file')
    parser.add_argument('--rig-units', choices=('m', 'cm', 'mm'), default=None,
                        help="the board's length unit (that of --square-length), written "
                        'into the outputs (default: camera centres >= 50 apart -> mm, else m)')
    parser.add_argument('--format', choices=FORMATS, default='anipose',
                        help='anipose calibration.toml, project rig YAML, or both')
    parser.add_argument('--distortion', choices=DISTORTION_MODELS,
                        default=defaults.distortion, help='lens distortion model')
    parser.add_argument('--fix-principal-point', action='store_true',
                        help='hold the principal point at the image centre')
    parser.add_argument('--free-aspect', action='store_true', help='fit fx and fy apart')
    parser.add_argument('--intrinsics', metavar='CAL', help='keep the intrinsics of this '
                        'calibration (any format load_rig reads); fit extrinsics only')
    parser.add_argument('--names', help='camera names, comma separated, in INPUT order')
    parser.add_argument('--timestamps', metavar='CSV', help='pair frames by time '
                        '(camera,frame,time_s)')
    parser.add_argument('--tolerance', type=float, default=None,
                        help='--timestamps pairing tolerance (s)')
    parser.add_argument('--loss', choices=LOSSES, default=defaults.loss,
                        help='robust loss of the bundle adjustment')
    parser.add_argument('--f-scale', type=float, default=defaults.f_scale_px,
                        help='robust loss scale (px)')
    parser.add_argument('--min-views', type=int, default=defaults.min_views,
                        help='warn when a camera has fewer board views')
    parser.add_argument('--report', help='PNG report path (default: OUT_report.png)')
    parser.add_argument('--no-report', action='store_true', help='no PNG report')
    parser.add_argument('--quiet', action='store_true', help='no progress bars')


def board_from_args(args):
    """The Board of --board or of the board options (not both)."""
    from monet_ros.calibration.board import BoardError, board_from_mapping, load_board
    given = {k: getattr(args, k) for k in BOARD_OPTIONS if getattr(args, k) is not None}
    if args.board and given:
        raise ValueError('--board: give a board file or the board options '
                         f'(--{next(iter(given)).replace("_", "-")}), not both')
    if args.board:
        return load_board(args.board)
    if not given:
        raise ValueError('--board: a board TOML (or --board-x, --board-y, --square-length, '
                         '...) is needed')
    if 'board_type' in given:
        given['type'] = given.pop('board_type')
    try:
        return board_from_mapping(given)
    except BoardError as error:      # name the option, not the TOML field
        option = 'board-type' if error.field == 'type' else error.field.replace('_', '-')
        raise ValueError(f'--{option}: {error.message}') from None


def _short(names):
    """Drop a prefix / suffix every name shares when it ends / starts at a separator."""
    if len(names) < 2:
        return names
    prefix = names[0]
    for n in names[1:]:
        while not n.startswith(prefix):
            prefix = prefix[:-1]
    prefix = prefix[:max((prefix.rfind(s) + 1 for s in '-_. '), default=0)]
    suffix = names[0]
    for n in names[1:]:
        while not n.endswith(suffix):
            suffix = suffix[1:]
    cut = [suffix.find(s) for s in '-_. ' if s in suffix]
    suffix = suffix[min(cut):] if cut else ''
    out = [n[len(prefix):len(n) - len(suffix)] for n in names]
    return out if all(out) and len(set(out)) == len(out) else names


def input_names(paths):
    """Distinct names of the inputs: the file stem / folder name, walking up to a parent
    folder while names repeat (back/calibration_images -> back)."""
    paths = [Path(p).resolve() for p in paths]
    names = [p.stem if p.is_file() else p.name for p in paths]
    depth = 0
    while len(set(names)) < len(names) and depth < 8:
        depth += 1
        names = [p.parents[depth - 1].name if len(p.parents) >= depth else n
                 for p, n in zip(paths, names)]
    if len(set(names)) < len(names):
        raise ValueError('INPUT: cannot name the cameras apart; give --names')
    return names


def camera_names(args, rig_names=None):
    """Names of the inputs in order (--names, the --intrinsics cameras, or the paths)."""
    if args.names:
        names = [n.strip() for n in args.names.split(',')]
        if len(names) != len(args.inputs) or not all(names) or len(set(names)) < len(names):
            raise ValueError(f'--names: {len(args.inputs)} distinct names are needed (one per '
                             f'INPUT), got {args.names!r}')
        return names
    raw = input_names(args.inputs)
    if rig_names is None:
        return _short(raw)
    out = []
    for r in raw:      # the calibration camera whose name the input's contains (longest)
        hits = [c for c in rig_names if c in r]
        hits = [c for c in hits if not any(len(o) > len(c) and c in o for o in hits)]
        if len(hits) != 1:
            raise ValueError(f'--intrinsics: input {r!r} matches '
                             + (f'cameras {", ".join(hits)}' if hits else 'no camera')
                             + f' of the calibration ({", ".join(rig_names)}); give --names')
        out.append(hits[0])
    if len(set(out)) < len(out):
        raise ValueError(f'--intrinsics: two inputs match the same camera ({", ".join(out)});'
                         ' give --names')
    return out


def _sources(args, names):
    from monet_ros.io.frame_sources import IMAGE_SUFFIXES, FrameSource
    sources = []
    for path, name in zip(args.inputs, names):
        p = Path(path)
        if not p.exists():
            raise ValueError(f'INPUT {path}: no such file or folder')
        if p.is_dir() and not any(f.suffix.lower() in IMAGE_SUFFIXES for f in p.iterdir()):
            raise ValueError(f'INPUT {path} (camera {name!r}): no image '
                             f'({", ".join(IMAGE_SUFFIXES)}) in the folder')
        sources.append(FrameSource(p, skip_unreadable=True))
    return sources


def _frames(source):
    while True:
        frame = source.read()
        if frame is None:
            return
        yield frame[1]


def open_inputs(args, names):
    """Frame sources of the inputs; with index pairing the image folders' frame counts
    (exact, unlike a video's) must agree before anything is detected."""
    sources = _sources(args, names)
    exact = {n: s.count for n, s in zip(names, sources) if s.files is not None}
    if not args.timestamps and len(set(exact.values())) > 1:
        for s in sources:
            s.close()
        raise ValueError('frame counts do not match across cameras (' + ', '.join(
            f'{n}: {c}' for n, c in exact.items()) + '); pair frames with --timestamps CSV')
    return sources


def detect_all(args, board, names, sources):
    """(CameraDetections of every input (tqdm progress per camera unless --quiet), {camera:
    [why each unreadable image is, naming the file]})."""
    from monet_ros.calibration.detect import BoardDetector, detect_frames
    try:
        detector = BoardDetector(board)
        detections = [detect_frames(n, _frames(s), board, total=s.count or None,
                                    progress=not args.quiet, detector=detector)
                      for n, s in zip(names, sources)]
        return detections, {n: list(s.unreadable) for n, s in zip(names, sources)}
    finally:
        for s in sources:
            s.close()


def _report_path(args):
    if args.report:
        return Path(args.report)
    out = Path(args.out)
    return out.with_name(out.stem + '_report.png')


def _check_args(args):
    if args.tolerance is not None and not args.tolerance > 0:
        raise ValueError(f'--tolerance must be positive (s), got {args.tolerance}')
    if args.tolerance is not None and not args.timestamps:
        raise ValueError('--tolerance is for --timestamps')
    if len(args.inputs) != len(set(Path(p).resolve() for p in args.inputs)):
        raise ValueError('INPUT: the same input is given twice')
    out = Path(args.out)
    if out.is_dir():
        raise ValueError(f'--out {out}: is a folder (give a file name)')
    # its folder is made when the outputs are written (as other commands make their --out);
    # here: the nearest existing folder above it is a folder this user can write in
    above = next(p for p in (out.parent, *out.parent.parents) if p.exists() or p.is_symlink())
    if not above.is_dir():
        raise ValueError(f'--out {out}: {above} is not a folder')
    if not os.access(above, os.W_OK | os.X_OK):
        raise ValueError(f'--out {out}: folder {above} is not writable')


def run(args):
    import numpy as np

    from monet_ros.calibration.pairing import apply_pairing, pair_by_time, read_timestamps
    from monet_ros.calibration.report import write_report
    from monet_ros.calibration.rig import CalibrationConfig, calibrate_rig, stack_detections
    from monet_ros.calibration.summary import board_geometry, summary_lines
    from monet_ros.geometry import load_rig, save_anipose_toml, save_rig
    from monet_ros.geometry.units import infer_units, with_units

    _check_args(args)
    board = board_from_args(args)
    config = CalibrationConfig(distortion=args.distortion, square_pixels=not args.free_aspect,
                               fix_principal_point=args.fix_principal_point, loss=args.loss,
                               f_scale_px=args.f_scale, min_views=args.min_views)
    fixed = None
    if args.intrinsics:
        rig = load_rig(args.intrinsics)
        names = camera_names(args, [c.name for c in rig])
        fixed = {c.name: c for c in rig}
    else:
        names = camera_names(args)
    sources = open_inputs(args, names)
    for source in sources:
        if source.order_note:
            print(f'monet calibrate: note: {source.order_note}', file=sys.stderr)
    print(f'monet calibrate: board {board.describe()}; cameras '
          + ', '.join(f'{n} <- {p}' for n, p in zip(names, args.inputs)), file=sys.stderr)
    detections, unreadable = detect_all(args, board, names, sources)
    for d in detections:
        found = len(d.no_board) - len(d.mirrored) - len(d.unreadable)
        print(f'monet calibrate: {d.name}: {len(d.corners)} frames, board in '
              f'{d.frames_with_board}, no board in {found}'
              + (f', board only mirrored in {len(d.mirrored)}' if d.mirrored else '')
              + (f', unreadable {len(d.unreadable)}' if d.unreadable else ''),
              file=sys.stderr)
        for why in unreadable[d.name]:
            print(f'monet calibrate: {d.name}: unreadable: {why}', file=sys.stderr)
        if d.hint:
            print(f'monet calibrate: {d.name}: no board view: {d.hint}', file=sys.stderr)
    if args.timestamps:
        times = read_timestamps(args.timestamps, names, {d.name: len(d.corners)
                                                          for d in detections})
        pairing = pair_by_time(times, names, args.tolerance)
        detections = apply_pairing(detections, pairing)
        unpaired = {n: int((pairing[:, c] < 0).sum()) for c, n in enumerate(names)}
        print(f'monet calibrate: {len(pairing)} instants paired by time; instants without a '
              f'frame: {unpaired}', file=sys.stderr)
    corners = stack_detections(detections)
    result = calibrate_rig(detections, board, config, fixed)
    units = args.rig_units
    if units is None:
        units, reason = infer_units(result.cameras)
        print(f'monet calibrate: note: the board states no length unit; {reason}: the '
              f'calibration is taken as {units} (--rig-units m|cm|mm states it)',
              file=sys.stderr)
    cameras = with_units(result.cameras, units)
    geometry = board_geometry(result, corners, board)
    out = Path(args.out)
    metadata = {'generator': 'monet calibrate', 'board': board.describe(),
                'distortion': 'fixed (--intrinsics)' if fixed else args.distortion,
                'error_px': float(result.errors.mean()),
                'board_square_triangulated': geometry['median']}
    written = []
    out.parent.mkdir(parents=True, exist_ok=True)
    if args.format in ('anipose', 'both'):
        save_anipose_toml(out, cameras, metadata)
        written.append(out)
    if args.format == 'rig':
        save_rig(out, cameras)
        written.append(out)
    if args.format == 'both':
        save_rig(out.with_suffix('.yaml'), cameras)
        written.append(out.with_suffix('.yaml'))
    if not args.no_report:
        write_report(_report_path(args), result, corners, board)
        written.append(_report_path(args))
    for line in summary_lines(result, corners, board, detections):
        print(line)
    for warning in result.warnings:
        print(f'monet calibrate: WARNING: {warning}', file=sys.stderr)
    if not np.isfinite(geometry['median']) or abs(geometry['error_pct']) > 2.0:
        print('monet calibrate: WARNING: the board triangulated back does not have its '
              'square length (see "board geometry" above)', file=sys.stderr)
    print('monet calibrate: wrote ' + ', '.join(map(str, written)), file=sys.stderr)
    return 0

