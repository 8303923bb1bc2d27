"""The `monet` command: offline jobs and the all-in-one pipeline.

Each subcommand lives in its own module under monet_ros/commands with
`HELP` (one line), `add_arguments(parser)` and `run(args) -> int`.
"""
import argparse
import importlib
import sys

# Subcommand name -> module under monet_ros.commands. Keep in the order of DESIGN.md.
SUBCOMMANDS = {
    'synth': 'synth',
    'train': 'train',
    'eval': 'eval',
    'demo': 'demo',
    'process': 'process',
    'pipeline': 'pipeline',
    'import': 'import_videos',
    'labels': 'labels',
    'info': 'info',
}


def build_parser():
    parser = argparse.ArgumentParser(
        prog='monet', description='MONET multiview keypoint tracking: offline jobs and pipeline.')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND')
    sub.required = True
    for name, module_name in SUBCOMMANDS.items():
        module = importlib.import_module(f'monet_ros.commands.{module_name}')
        command = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(command)
        command.set_defaults(handler=module.run)
    return parser


def main(argv=None):
    args = build_parser().parse_args(argv)
    try:
        return int(args.handler(args) or 0)
    except KeyboardInterrupt:
        return 130


if __name__ == '__main__':
    sys.exit(main())
