"""Subcommands of the `monet` command, one module each (see monet_ros/cli.py)."""
