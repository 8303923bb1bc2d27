"""Every `monet` command (and subcommand) that reads a rig (--rig, --calibration,
--intrinsics) has --rig-units m|cm|mm; a bad value is argparse's one-line error, exit 2."""
import argparse

from monet_ros.cli import build_parser
from monet_ros.cli import main as monet

RIG_OPTIONS = ('--rig', '--calibration', '--intrinsics')


def parsers(parser, prog='monet'):
    """(prog, parser) of every (sub)command below `parser`."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield f'{prog} {name}', sub
                yield from parsers(sub, f'{prog} {name}')


def test_every_command_that_reads_a_rig_takes_rig_units():
    reading = {}
    for prog, parser in parsers(build_parser()):
        options = {o: a for a in parser._actions for o in a.option_strings}
        if any(o in options for o in RIG_OPTIONS):
            reading[prog] = options.get('--rig-units')
    assert {'monet triangulate', 'monet process', 'monet train', 'monet eval',
            'monet pipeline', 'monet info', 'monet label', 'monet labels import',
            'monet import videos', 'monet calibrate'} <= set(reading)
    missing = [prog for prog, action in reading.items() if action is None]
    assert not missing, missing
    for prog, action in reading.items():
        assert tuple(action.choices) == ('m', 'cm', 'mm') and action.default is None, prog


def test_a_bad_rig_unit_is_one_line_exit_2(capsys):
    assert monet(['triangulate', 'x.csv', '--rig', 'r.toml', '--out', 'o',
                  '--rig-units', 'inch']) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--rig-units: invalid choice: 'inch'" in err[0]
