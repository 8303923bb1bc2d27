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
    """--backend, --precision and --calibration of the commands that run the detector
    (monet process, monet pipeline): one help text; `calibration_default` names what int8
    calibrates on when --calibration is not given."""
    from monet_ros.models.detector import PRECISIONS
    from monet_ros.models.onnx_backend import BACKEND_CHOICES
    parser.add_argument('--backend', choices=BACKEND_CHOICES, default='auto',
                        help='detector inference backend: auto (default: onnxruntime for '
                        'float32 and int8 on a CPU, torch for bfloat16 and on a GPU: '
                        'models.detector.resolve_backend; the choice is printed), torch, or '
                        'onnxruntime (exported once, cached beside the checkpoint)')
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

def print_precision(owner, precision, backend='torch', device=None, checkpoint=None,
                    calibration=None):
    """precision_note(...) with its line printed (stdout, `owner: precision auto: ...`:
    stderr keeps one line for a bad input); returns the precision run."""
    chosen, note = precision_note(owner, precision, backend, device, checkpoint, calibration)
    print(f'{owner}: {note}', flush=True)
    return chosen


def precision_note(owner, precision, backend='torch', device=None, checkpoint=None,
                   calibration=None):
    """Resolve --precision (auto: bfloat16 with torch where native, else float32; int8 only when
    asked for) and --backend (auto: models.detector.resolve_inference) for `device` (None =
    CUDA when present, else CPU): (the precision run, the note saying which and why),
    nothing printed (`monet pipeline` prints it once every start check passed). ConfigError
    names precision for a value that cannot run (bfloat16 on a CPU that would emulate it,
    int8 without onnxruntime or without VNNI / AMX-INT8); ConfigError names calibration
    when one (--calibration, int8's data) is given for another precision (nothing would use
    it)."""
    import torch

    from monet_ros.models.detector import resolve_inference
    if device is None:
        device = 'cuda' if torch.cuda.is_available() else 'cpu'
    try:
        chosen, _, note = resolve_inference(precision, backend, device, checkpoint)
    except ValueError as error:
        field = 'backend' if str(error).startswith('backend') else 'precision'
        raise ConfigError(owner, field, str(error)) from None
    if calibration is not None and chosen != 'int8':
        raise ConfigError(owner, 'calibration', f'{calibration}: calibration data of '
                          f'--precision int8 only; this run is {chosen} (give --precision '
                          'int8 --backend onnxruntime, or leave --calibration out)')
    return chosen, note


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
def made_output_dir(path):
    """Make the output folder `path` (and its missing parents) for a command that writes
    into it as it goes; yields it. When the command fails or is stopped (any exception,
    Ctrl-C / SIGTERM as KeyboardInterrupt) the folders made here that are still empty are
    removed (deepest first), so a stopped run leaves no empty folder behind; a folder that
    existed before is kept. OSError naming the path when it cannot be made."""
    path = Path(path)
    made, folder = [], path
    while not (folder.exists() or folder.is_symlink()) and folder != folder.parent:
        made.append(folder)
        folder = folder.parent
    path.mkdir(parents=True, exist_ok=True)
    try:
        yield path
    except BaseException:
        for folder in made:
            try:
                folder.rmdir()                 # only when empty
            except OSError:
                break
        raise


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


def check_subject_only_options(args, several, command,
                               needs='--subjects N (N >= 2)',
                               without='runs one subject without it'):
    """ValueError naming the first --subjects-only option given a value other than its
    default when `several` is false (one subject): such a value would be ignored. needs /
    without: what the option needs and what the command does without it (the error's
    words; `monet train`'s teacher options need distillation and labels of several
    subjects)."""
    if several:
        return
    check_applies([names for dest, (default, names) in
                   (getattr(args, 'subject_only_defaults', None) or {}).items()
                   if getattr(args, dest) != default], False, command, needs, without)


def check_applies(given, applies, command, needs, without):
    """ValueError '{option} applies only with {needs}; {command} {without}' naming the first
    of `given` (the options the user gave, as typed names) when `applies` is false: a value
    the run would ignore is refused, not dropped silently."""
    if given and not applies:
        raise ValueError(f'{given[0]} applies only with {needs}; {command} {without}')


def changed_options(config, options):
    """['--option value', ...] of the fields of `config` (options: {option: field},
    config_options) whose value is not the field's default, in `options`' order; a bool as
    --x / --no-x: the options a command line needs to give that config."""
    from dataclasses import fields
    defaults = {f.name: f.default for f in fields(config)}
    out = []
    for option, name in options.items():
        value = getattr(config, name)
        if value == defaults[name]:
            continue
        if isinstance(value, bool):
            out.append(option if value else '--no-' + option[2:])
        else:
            out.append(f'{option} {value:g}' if isinstance(value, float) else
                       f'{option} {value}')
    return out


def config_options(config_cls, exclude=(), rename=None):
    """{option: field} of the init fields of a config dataclass (monet_ros.config), in
    field order: each as --its-name (underscores as dashes), except those in `exclude` and
    those `rename` ({field: option}) spells otherwise (a name another option of the
    command already has)."""
    from dataclasses import fields
    rename = rename or {}
    return {rename.get(f.name, '--' + f.name.replace('_', '-')): f.name
            for f in fields(config_cls) if f.init and f.name not in exclude}


def add_config_options(parser, config_cls, options, add=None, help_prefix=''):
    """One option per entry of `options` ({option: field}, config_options) with the field's
    type (monet_ros.config.field_kind; a bool is --x / --no-x), default and description
    (the help, after `help_prefix`, with the default): the config is the one place of
    each. add(parser, option, **kwargs): how to add it (default parser.add_argument; e.g.
    subject_only_option). The value is args.<option without dashes, dashes as
    underscores>; config_from_options builds the config."""
    from dataclasses import fields

    from monet_ros.config import field_kind
    add = add or (lambda p, option, **kwargs: p.add_argument(option, **kwargs))
    declared = {f.name: f for f in fields(config_cls)}
    for option, name in options.items():
        f = declared[name]
        kind, is_tuple = field_kind(config_cls, name)
        if is_tuple:
            raise TypeError(f'{config_cls.__name__}.{name}: a tuple setting has no option')
        text = help_prefix + f.metadata['description'].replace('%', '%%') + \
            ' (default %(default)s)'
        if kind is bool:
            add(parser, option, action=argparse.BooleanOptionalAction, default=f.default,
                help=text)
        else:
            add(parser, option, type=kind, default=f.default, help=text)


def option_dest(option):
    """argparse's attribute of an option: '--gate-mm' -> 'gate_mm'."""
    return option[2:].replace('-', '_')


def config_from_options(args, config_cls, options, derive=None, **values):
    """config_cls of the options (add_config_options) in `args` plus `values` (fields set
    otherwise). derive(config): what the settings feed, refused unless usable
    (monet_ros.config.derive_checked: a value that overflows names its field). A
    ConfigError of one of those fields becomes a ValueError naming the option as typed,
    then the setting: `--track-measurement-noise-mm: TrackerConfig: parameter
    'measurement_noise_mm': must be > 0.0, got -1.0` (the option's name need not be the
    field's); others pass as they are."""
    from monet_ros.config import derive_checked
    given = {name: getattr(args, option_dest(option)) for option, name in options.items()}
    with options_named(config_cls, options):
        config = config_cls(**given, **values)
        if derive is not None:
            derive_checked(config_cls.__name__, config, derive)
        return config


@contextmanager
def options_named(config_cls, options):
    """A ConfigError of a config_cls field in `options` ({option: field}) raised inside
    becomes a ValueError naming the option as typed, then the setting (config_from_options'
    format); others pass as they are. For checks made after construction too (e.g.
    FilterConfig.in_units once the rig's unit is known)."""
    try:
        yield
    except ConfigError as error:
        option = next((o for o, n in options.items() if n == error.field), None)
        if option is None or error.owner != config_cls.__name__:
            raise
        raise ValueError(f'{option}: {error}') from None


def tracker_options():
    """{option: field} of subjects.tracking.TrackerConfig, every field, as options of
    `monet process --subjects` and `monet triangulate --subjects`: --its-name (--gate-mm,
    ...), but the per-joint filter's measurement_noise_mm / acceleration_m_s2 as
    --track-measurement-noise-mm / --track-acceleration-m-s2 (the plain names are the
    --filter's, commands.filter_options)."""
    from monet_ros.subjects.tracking import TrackerConfig
    return config_options(TrackerConfig, rename={
        'measurement_noise_mm': '--track-measurement-noise-mm',
        'acceleration_m_s2': '--track-acceleration-m-s2'})


def add_subject_tracking_arguments(parser, help_prefix='--subjects: '):
    """--association-px and every tracker setting (tracker_options): the association and
    tracker settings of `monet triangulate --subjects` and `monet process --subjects`
    (subjects.association, subjects.tracking), all --subjects-only."""
    from monet_ros.subjects.tracking import TrackerConfig
    subject_only_option(parser, '--association-px', type=float, default=15.0,
                        help=f'{help_prefix}largest median epipolar distance (px) between two '
                        'instances of one subject (default %(default)s)')
    add_config_options(parser, TrackerConfig, tracker_options(), add=subject_only_option,
                       help_prefix=help_prefix)


def tracker_config_from_args(args):
    """The subjects.tracking.TrackerConfig of the tracker options (add_subject_tracking_
    arguments); ValueError naming the option of a bad value (config_from_options), also of
    one the tracker cannot use in some rig unit (a noise whose square overflows, e.g.
    --body-noise-mm 1e200: checked by making the tracker in m, cm and mm, before any
    file is read)."""
    from monet_ros.geometry.units import UNITS
    from monet_ros.subjects.tracking import SubjectTracker, TrackerConfig
    return config_from_options(
        args, TrackerConfig, tracker_options(),
        derive=lambda config: [SubjectTracker(1, config, units=u) for u in UNITS])


ASSOCIATION_OPTIONS = {'--association-px': 'threshold_px'}   # subjects.AssociationConfig


def subjects_options():
    """{option: field} of subjects.detection.SubjectsConfig but `subjects` (--subjects N):
    the detector's several-subject options of `monet process`."""
    from monet_ros.subjects.detection import SubjectsConfig
    return config_options(SubjectsConfig, exclude=('subjects',))


def add_subjects_detection_arguments(parser):
    """--subjects N and the subjects.detection.SubjectsConfig options of `monet process`
    (subjects_options; help: the config's field descriptions), with
    add_subject_tracking_arguments (add_subject_settings_arguments)."""
    parser.add_argument('--subjects', type=int, default=1, metavar='N',
                        help='several subjects (N >= 2): per-subject crops tracked over time, '
                        'found by full-frame candidates; per-subject outputs as `monet '
                        'triangulate --subjects` (1 = one subject, the tracked crop)')
    add_subject_settings_arguments(parser)


def add_subject_settings_arguments(parser, help_prefix='--subjects: '):
    """The several-subject settings of `monet process --subjects N` without --subjects:
    the SubjectsConfig options (subjects_options), --association-px and the tracker's
    (add_subject_tracking_arguments), every one --subjects-only (subject_only_option;
    help_prefix: what their help starts with). `monet train` declares its distillation
    teacher's with it: the same names, defaults, help and validation
    (process.subject_configs)."""
    from monet_ros.subjects.detection import SubjectsConfig
    add_config_options(parser, SubjectsConfig, subjects_options(), add=subject_only_option,
                       help_prefix=help_prefix)
    add_subject_tracking_arguments(parser, help_prefix)
