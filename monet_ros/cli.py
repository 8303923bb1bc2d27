"""The `monet` command: offline jobs and the all-in-one pipeline.

Each subcommand lives in its own module under monet_ros/commands with
`HELP` (one line), `add_arguments(parser)` and `run(args) -> int`.

Exit codes, the same for every subcommand: 0 on success and on SIGINT / SIGTERM (a clean
stop at any moment); 2 with ONE line on stderr naming the file, field or option and the
reason for bad input (an argument, a file, a model, an output folder that cannot be
written); 1 with one line for an internal error (a bug: MONET_TRACEBACK=1 shows its
traceback).
"""
import argparse
from contextlib import contextmanager
import difflib
import importlib
import os
import signal
import sys
import threading

from monet_ros.error_text import error_line
from monet_ros.stop_signals import ignore_stop_signals, interrupt_on_stop, raise_interrupt

EXIT_OK = 0
EXIT_INTERNAL = 1
EXIT_BAD_INPUT = 2

# Subcommand name -> module under monet_ros.commands. Keep in the order of DESIGN.md.
SUBCOMMANDS = {
    'synth': 'synth',
    'train': 'train',
    'eval': 'eval',
    'demo': 'demo',
    'process': 'process',
    'triangulate': 'triangulate',
    'pipeline': 'pipeline',
    'import': 'import_videos',
    'calibrate': 'calibrate',
    'labels': 'labels',
    'info': 'info',
    'label': 'label',
}


class OneLineParser(argparse.ArgumentParser):
    """argparse with one-line errors (`monet train: error: argument --steps: ...`), exit 2."""

    def error(self, message):
        self.exit(EXIT_BAD_INPUT, f'{self.prog}: error: {message}\n')

    def parse_known_args(self, args=None, namespace=None):
        """Unknown options of a command are reported first, by the command, with the
        closest known one: `monet triangulate: error: unrecognized arguments: --rgi (did
        you mean --rig?)`; argparse alone would report only the required option a typo
        hides, under the top parser's name."""
        if args is not None and not any(isinstance(a, argparse._SubParsersAction)
                                        for a in self._actions):
            unknown = [a for a in self._unknown_options(args)]
            if unknown:
                known = [o for o in self._option_string_actions if o.startswith('--')]
                hints = []
                for option in unknown:
                    close = difflib.get_close_matches(option.split('=', 1)[0], known, n=1,
                                                    cutoff=0.75)
                    hints.append(f'{option} (did you mean {close[0]}?)' if close else option)
                self.error('unrecognized arguments: ' + ' '.join(hints))
        return super().parse_known_args(args, namespace)

    def _unknown_options(self, args):
        """The `--name` tokens of args (before a bare `--`) that name no option of this
        parser, neither exactly nor as a prefix (argparse's abbreviations)."""
        options = [o for o in self._option_string_actions if o.startswith('--')]
        for token in args:
            if token == '--':
                return
            if not token.startswith('--'):
                continue
            name = token.split('=', 1)[0]
            if name in self._option_string_actions:
                continue
            if self.allow_abbrev and any(o.startswith(name) for o in options):
                continue            # a prefix: argparse resolves it or says it is ambiguous
            yield token


def build_parser():
    parser = OneLineParser(
        prog='monet', description='MONET multiview keypoint tracking: offline jobs and pipeline.')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND',
                                parser_class=OneLineParser)
    sub.required = True
    for name, module_name in SUBCOMMANDS.items():
        module = importlib.import_module(f'monet_ros.commands.{module_name}')
        command = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(command)
        command.set_defaults(handler=module.run)
    return parser


@contextmanager
def sigterm_as_interrupt():
    """SIGTERM raises KeyboardInterrupt (a clean stop, exit 0) while the command runs."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, raise_interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def bad_input_errors():
    """Exception types that mean bad input (their messages name the thing)."""
    errors = [ValueError, OSError, MemoryError]
    try:
        from monet_ros.models import CheckpointError
        errors.append(CheckpointError)
    except ImportError:                                # pragma: no cover
        pass
    return tuple(errors)


def given_option(error, argv):
    """'--link-mm: ' when `error` is a ConfigError of a setting the user gave as that
    option on the command line (the config's field, dashes for underscores), else ''. So
    the line names what was typed, not only the setting inside (a value from a file or a
    default is not attributed to an option)."""
    field = getattr(error, 'field', None)
    if not isinstance(field, str) or not field:
        return ''
    option = '--' + field.replace('_', '-')
    given = any(a == option or a.startswith(option + '=') for a in argv)
    return f'{option}: ' if given else ''


def main(argv=None):
    """Run `monet ARGV`; returns the exit code (see the module docstring)."""
    name = 'monet'
    try:
        with sigterm_as_interrupt():
            argv = list(sys.argv[1:] if argv is None else argv)
            ros_args = []
            if '--ros-args' in argv:      # ROS arguments for the nodes of `monet pipeline`
                index = argv.index('--ros-args')
                argv, ros_args = argv[:index], argv[index:]
            parser = build_parser()
            args = parser.parse_args(argv)
            args.ros_args = ros_args
            name = f'monet {args.command}'
            if ros_args and args.command != 'pipeline':
                parser.error('--ros-args is only for `monet pipeline` (its ROS nodes)')
            try:
                return int(args.handler(args) or 0)
            except bad_input_errors() as error:
                if os.environ.get('MONET_TRACEBACK'):
                    raise
                line = error_line(error, name, output=getattr(args, 'out', None))
                print(f'{name}: error: {given_option(error, argv)}{line}',
                      file=sys.stderr, flush=True)
                return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print(f'{name}: stopped', file=sys.stderr, flush=True)
        return EXIT_OK
    except SystemExit as exit_:
        return exit_.code if isinstance(exit_.code, int) else EXIT_BAD_INPUT
    except Exception as error:  # noqa: BLE001 - one line, never a traceback, for users
        if os.environ.get('MONET_TRACEBACK'):
            raise
        print(f'{name}: internal error: {type(error).__name__}: {error_line(error)} '
              '(MONET_TRACEBACK=1 shows where)', file=sys.stderr, flush=True)
        return EXIT_INTERNAL


def console_main():
    """Run main(), then exit with its code: the `monet` executable (through
    monet_ros.entry.monet, which makes a signal during the imports before this exit 0) and
    `python -m monet_ros.cli` (there a signal while this module is still being imported has
    Python's defaults). SIGINT and SIGTERM raise KeyboardInterrupt from the first moment
    main() can see it (main: `monet ...: stopped`, exit 0), and once the command has
    returned both signals are ignored, so a SIGINT / SIGTERM that lands after the work
    (while main returns or Python shuts down: torch's exit hooks take up to a second) exits
    0 and quietly instead of killing the process by the signal (-2 / -15) or printing a
    KeyboardInterrupt traceback from an exit hook (monet_ros.stop_signals)."""
    code = EXIT_OK
    try:
        interrupt_on_stop()
        code = main()
    except KeyboardInterrupt:         # landed between main's own handling and its return
        code = EXIT_OK
    finally:
        ignore_stop_signals()
    sys.exit(code)


if __name__ == '__main__':
    console_main()
