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
    argv = list(sys.argv[1:] if argv is None else argv)
    ros_args = []
    if '--ros-args' in argv:      # ROS arguments for the nodes of `monet pipeline`
        index = argv.index('--ros-args')
        argv, ros_args = argv[:index], argv[index:]
    parser = build_parser()
    args = parser.parse_args(argv)
    args.ros_args = ros_args
    if ros_args and argv[:1] != ['pipeline']:
        parser.error('--ros-args is only for `monet pipeline` (its ROS nodes)')
    try:
        return int(args.handler(args) or 0)
    except KeyboardInterrupt:
        return 130


if __name__ == '__main__':
    sys.exit(main())
