"""What every `monet` subcommand shares: bounded option checks and output folders written
atomically (their messages name the path or option, not a subcommand)."""
import argparse
from contextlib import contextmanager
import os
from pathlib import Path
import shutil
import tempfile

from monet_ros.config import ConfigError

# Upper bound of --threads (a typo such as 10000 would spawn that many threads).
MAX_THREADS = 256


def check_threads(owner, threads):
    """Validate a --threads value (0 = torch default) and apply it. ConfigError names it."""
    if isinstance(threads, bool) or not isinstance(threads, int) or not \
            0 <= threads <= MAX_THREADS:
        raise ConfigError(owner, 'threads', f'must be an integer in 0..{MAX_THREADS}, '
                          f'got {threads!r}')
    if threads:
        import torch
        torch.set_num_threads(threads)



def add_precision_options(parser, calibration_default):
    """--precision and --calibration of the commands that run the detector (monet process,
    monet pipeline): one help text; `calibration_default` names what int8 calibrates on
    when --calibration is not given."""
    from monet_ros.models.detector import PRECISIONS
    parser.add_argument('--precision', choices=PRECISIONS, default='auto',
                        help='network arithmetic: auto (default: bfloat16 with torch where '
                        'native, else float32; never int8, measured slower; the choice is '
                        'printed), float32, bfloat16 (torch backend, 2-3x faster on CPUs with '
                        'AVX512-BF16 / AMX and on CUDA), or int8 (--backend onnxruntime, CPU '
                        'with VNNI / AMX-INT8: quantised once, calibrated on the crops the '
                        'run makes (tracked crops around the subject, found by float32; full '
                        'frames with `monet process --no-track`), cached beside the '
                        'checkpoint per crop mode)')
    parser.add_argument('--calibration', default=None,
                        help='int8: the recording (tracked crops need its camera_info and '
                        '/tf_static) or a cached *.<crops>.int8.onnx quant of the same crop '
                        f'mode to calibrate on (default: {calibration_default})')

def print_precision(owner, precision, backend='torch', device=None, checkpoint=None):
    """Resolve --precision (auto: bfloat16 with torch where native, else float32; int8 only
    when asked for: models.detector.resolve_precision) for `device` (None = CUDA when
    present, else CPU) and print the one line saying which runs and why (stdout, `owner:
    precision auto: ...`: stderr keeps one line for a bad input); returns the precision
    run. ConfigError names precision for a value that cannot run (bfloat16 on a CPU that
    would emulate it, int8 without onnxruntime or without VNNI / AMX-INT8)."""
    import torch

    from monet_ros.models.detector import resolve_precision
    if device is None:
        device = 'cuda' if torch.cuda.is_available() else 'cpu'
    try:
        chosen, note = resolve_precision(precision, backend, device, checkpoint)
    except ValueError as error:
        raise ConfigError(owner, 'precision', str(error)) from None
    print(f'{owner}: {note}', flush=True)
    return chosen


def check_new_output(path, owner, field='out'):
    """An output folder that must not exist yet (or be an empty folder) in a place where a
    folder can be made: ConfigError naming it when it is a file or holds something, OSError
    naming it when its place is not writable (checked by making a folder there)."""
    path = Path(path)
    if path.exists() or path.is_symlink():
        if not path.is_dir():
            raise ConfigError(owner, field, f'{path}: exists and is not a folder')
        if any(path.iterdir()):
            raise ConfigError(owner, field, f'{path}: output exists and is not empty; not '
                              'overwriting (choose a new folder)')
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        Path(tempfile.mkdtemp(prefix=f'.{path.name}.', suffix='.probe', dir=path.parent)).rmdir()
    except OSError as error:
        raise OSError(error.errno, error.strerror, str(path)) from None


@contextmanager
def atomic_output_dir(path):
    """Yield a staging folder to write an output folder into; on success it is renamed to
    `path` (which must not exist, or be an empty folder), on any failure (or Ctrl-C) it is
    removed, so a failed run leaves nothing behind and can be rerun. The staging folder has
    the same name as `path` (inside a hidden temporary folder beside it), so files named
    after their folder (rosbag2's <folder>_0.mcap) keep the right name."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    holder = Path(tempfile.mkdtemp(prefix=f'.{path.name}.', suffix='.partial',
                                   dir=path.parent))
    staging = holder / path.name
    try:
        yield staging
        if path.is_dir() and not any(path.iterdir()):
            path.rmdir()
        os.replace(staging, path)
    finally:
        shutil.rmtree(holder, ignore_errors=True)


def add_rig_units_argument(parser):
    """--rig-units m|cm|mm: the length unit of a rig file that states none (anipose /
    Pose2Sim TOML, OpenCV, DANNCE); default: the file's, else the rule of geometry.units
    (camera centres >= 50 apart -> mm, else m; noted on stderr)."""
    from monet_ros.geometry.units import UNITS
    parser.add_argument('--rig-units', choices=UNITS, default=None,
                        help="length unit of a calibration that states none (default: the "
                        "file's `units`, else camera centres >= 50 apart -> mm, else m)")


def subject_only_option(parser, option, **kwargs):
    """parser.add_argument for an option that applies only with --subjects N (N >= 2);
    its default is remembered in the command's namespace (subject_only_defaults) for
    check_subject_only_options."""
    action = parser.add_argument(option, **kwargs)
    defaults = dict(parser.get_default('subject_only_defaults') or {})
    defaults[action.dest] = (action.default, ' / '.join(action.option_strings))
    parser.set_defaults(subject_only_defaults=defaults)
    return action


def check_subject_only_options(args, several, command):
    """ValueError naming the first --subjects-only option given a value other than its
    default when `several` is false (one subject): such a value would be ignored."""
    if several:
        return
    for dest, (default, names) in (getattr(args, 'subject_only_defaults', None) or {}).items():
        if getattr(args, dest) != default:
            raise ValueError(f'{names} applies only with --subjects N (N >= 2); {command} '
                             'runs one subject without it')


def add_subject_tracking_arguments(parser):
    """--association-px, --gate-mm, --max-missed-s: the association and tracker settings of
    `monet triangulate --subjects` and `monet process --subjects` (subjects.association,
    subjects.tracking)."""
    subject_only_option(parser, '--association-px', type=float, default=15.0,
                        help='--subjects: largest median epipolar distance (px) between two '
                        'instances of one subject')
    subject_only_option(parser, '--gate-mm', type=float, default=400.0,
                        help="--subjects: largest distance (mm) of a subject's body (the "
                        "median displacement of its joints) to a track's predicted body (a "
                        'track unmatched for t s: plus 2 m/s x t)')
    subject_only_option(parser, '--max-missed-s', type=float, default=0.5,
                        help='--subjects: a track unseen for longer (s) ends')


def add_subjects_detection_arguments(parser):
    """--subjects N and the subjects.detection.SubjectsConfig options of `monet process`
    (help: the config's field descriptions), with add_subject_tracking_arguments."""
    from dataclasses import fields

    from monet_ros.subjects.detection import SubjectsConfig
    d = {f.name: f for f in fields(SubjectsConfig)}
    parser.add_argument('--subjects', type=int, default=1, metavar='N',
                        help='several subjects (N >= 2): per-subject crops tracked over time, '
                        'found by full-frame candidates; per-subject outputs as `monet '
                        'triangulate --subjects` (1 = one subject, the tracked crop)')
    for name, kind in (('candidates', int), ('link_mm', float), ('crop_peaks', int),
                       ('duplicate_mm', float), ('crop_missed', int),
                       ('min_score', float)):
        subject_only_option(parser, '--' + name.replace('_', '-'), type=kind,
                            default=d[name].default,
                            help='--subjects: ' + d[name].metadata['description'])
    for name in ('rival_peaks', 'foreign_views'):
        subject_only_option(parser, '--' + name.replace('_', '-'),
                            action=argparse.BooleanOptionalAction, default=d[name].default,
                            help='--subjects: ' + d[name].metadata['description']
                            + ' (default: %(default)s)')
    add_subject_tracking_arguments(parser)
