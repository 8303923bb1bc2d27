"""The `monet` console script's target (setup.py EXECUTABLES: `monet_ros.entry:monet`).

SIGINT / SIGTERM exit 0 at any moment (monet_ros.stop_signals). The generated script runs
`from monet_ros.entry import monet; monet()`: this module (and monet_ros/__init__, which
stays light) imports only the standard library, and monet() installs the exit-0 handlers
before it imports monet_ros.cli. cli.console_main then installs the clean-stop handlers
before main() imports the commands and, through them, numpy, torch, cv2 ... With
`monet_ros.cli:console_main` as the target, a signal during the imports of monet_ros.cli
itself (about 12 ms of argparse, difflib ...) printed a KeyboardInterrupt traceback or killed
the process with -15.

The node executables (detector, fusion, learner, player) get the same handlers from the
monet_ros.nodes package, which is imported before their modules.

A window is left that no code of ours can close: the interpreter's own start-up (site,
.pth files such as the ROS wheels' re-exec of Python, the generated script's `import re,
sys`, then monet_ros/__init__ and this module's own standard-library imports) runs
before the handlers are in place; a signal then has Python's defaults (SIGINT: a
KeyboardInterrupt traceback, SIGTERM: killed, -15). About 60 ms here (Python 3.11 with the
ROS wheels' re-exec), against about 12 ms of monet_ros.cli's imports now covered.
"""
from monet_ros.stop_signals import exit_0_on_stop


def monet():
    """The `monet` executable: exit-0 handlers, then cli.console_main() (which exits with
    the command's code)."""
    exit_0_on_stop()
    from monet_ros.cli import console_main
    console_main()
