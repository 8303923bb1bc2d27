"""Every identity-tracker setting (subjects.tracking.TrackerConfig, also the fusion
node's parameters of the same names) is an option of `monet process --subjects` and
`monet triangulate --subjects`, with the config's defaults; a bad value is one line naming
the option (exit 2); without --subjects (one subject, no tracker) each is refused as
--gate-mm is. That they reach the tracker: test_triangulate_subjects.py
(test_tracker_options_decide_the_identities) and test_process_subjects.py."""
from dataclasses import fields

import pytest

from monet_ros.cli import build_parser
from monet_ros.cli import main as monet
from monet_ros.commands.common import tracker_config_from_args
from monet_ros.commands.process import subject_configs
from monet_ros.subjects.tracking import TrackerConfig

# what a user types -> the setting it is, and a value other than the default (written out
# here, not derived from the implementation: the options' names are what users rely on)
GIVEN = {'--gate-mm': ('gate_mm', 250.0), '--max-missed-s': ('max_missed_s', 0.8),
         '--min-keypoints': ('min_keypoints', 5),
         '--track-measurement-noise-mm': ('measurement_noise_mm', 9.0),
         '--track-acceleration-m-s2': ('acceleration_m_s2', 30.0),
         '--body-noise-mm': ('body_noise_mm', 70.0),
         '--body-acceleration-m-s2': ('body_acceleration_m_s2', 3.0),
         '--max-speed-m-s': ('max_speed_m_s', 1.5)}
COMMANDS = {'triangulate': ['triangulate', 'x.csv', '--rig', 'r.yaml', '--out', 'o'],
            'process': ['process', 'rec', '--model', 'm.pt', '--out', 'o']}


def _parse(argv):
    return build_parser().parse_args(argv)


def test_every_tracker_setting_is_given():
    assert sorted(name for name, _ in GIVEN.values()) == \
        sorted(f.name for f in fields(TrackerConfig))
    assert all(getattr(TrackerConfig(), name) != value for name, value in GIVEN.values())


@pytest.mark.parametrize('command', sorted(COMMANDS))
def test_the_options_build_the_tracker_config(command):
    words = [w for option, (_, value) in GIVEN.items() for w in (option, str(value))]
    args = _parse([*COMMANDS[command], '--subjects', '2', *words])
    expected = TrackerConfig(**dict(GIVEN.values()))
    assert tracker_config_from_args(args) == expected
    if command == 'process':
        assert subject_configs(args)[2] == expected
    # left out, each is the config's default (the fusion node's parameter default too)
    args = _parse([*COMMANDS[command], '--subjects', '2'])
    assert tracker_config_from_args(args) == TrackerConfig()


@pytest.mark.parametrize('command', sorted(COMMANDS))
def test_the_filters_options_stay_the_filters(command):
    # --measurement-noise-mm / --acceleration-m-s2 are the --filter's (FilterConfig); the
    # tracker's own are --track-...: typed together, each reaches its own config
    args = _parse([*COMMANDS[command], '--subjects', '2', '--measurement-noise-mm', '40',
                   '--track-measurement-noise-mm', '9', '--acceleration-m-s2', '12',
                   '--track-acceleration-m-s2', '30'])
    from monet_ros.commands.filter_options import filter_config_from_args
    filt = filter_config_from_args(args, 0.1, 15.0)
    assert (filt.measurement_noise_mm, filt.acceleration_m_s2) == (40.0, 12.0)
    tracker = tracker_config_from_args(args)
    assert (tracker.measurement_noise_mm, tracker.acceleration_m_s2) == (9.0, 30.0)


@pytest.mark.parametrize('command', sorted(COMMANDS))
@pytest.mark.parametrize('option, value, reason', [
    ('--body-noise-mm', '0', "TrackerConfig: parameter 'body_noise_mm': must be > 0.0, "
     'got 0.0'),
    ('--track-measurement-noise-mm', '-1', "TrackerConfig: parameter "
     "'measurement_noise_mm': must be > 0.0, got -1.0"),
    ('--max-speed-m-s', 'nan', "TrackerConfig: parameter 'max_speed_m_s': must be finite, "
     'got nan'),
    ('--min-keypoints', '0', "TrackerConfig: parameter 'min_keypoints': must be >= 1, got 0"),
    ('--max-missed-s', '-0.1', "TrackerConfig: parameter 'max_missed_s': must be >= 0.0, "
     'got -0.1'),
])
def test_a_bad_value_is_one_line_naming_the_option(command, option, value, reason, capsys,
                                                   tmp_path, monkeypatch):
    # refused before any file is read (x.csv, rec, m.pt do not exist); the filter's
    # --measurement-noise-mm typed beside it is not blamed
    monkeypatch.chdir(tmp_path)
    argv = [*COMMANDS[command], '--subjects', '2', '--measurement-noise-mm', '15', option,
            value]
    assert monet(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err == f'monet {command}: error: {option}: {reason}'
    assert not (tmp_path / 'o').exists()


@pytest.mark.parametrize('command', sorted(COMMANDS))
@pytest.mark.parametrize('option, field', [('--body-noise-mm', 'body_noise_mm'),
                                           ('--track-acceleration-m-s2', 'acceleration_m_s2')])
def test_a_value_whose_square_overflows_is_one_line_naming_the_option(
        command, option, field, capsys, tmp_path, monkeypatch):
    # valid as a number, but the tracker squares it in the rig's unit: refused before any
    # file is read (was an internal error, exit 1, once the tracker was made)
    monkeypatch.chdir(tmp_path)
    assert monet([*COMMANDS[command], '--subjects', '2', option, '1e200']) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"monet {command}: error: {option}: TrackerConfig: parameter "
                          f"'{field}': 1e+200 cannot be used: OverflowError") and \
        '\n' not in err, err


@pytest.mark.parametrize('command', sorted(COMMANDS))
def test_a_value_argparse_cannot_read_is_one_line(command, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert monet([*COMMANDS[command], '--subjects', '2', '--min-keypoints', '2.5']) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"monet {command}: error: argument --min-keypoints: invalid int value: "
                   "'2.5'")


@pytest.mark.parametrize('command', sorted(COMMANDS))
@pytest.mark.parametrize('option', sorted(GIVEN))
def test_without_subjects_each_is_refused_as_gate_mm(command, option, capsys, tmp_path,
                                                    monkeypatch):
    # one subject runs no tracker: a value would be ignored, so it is refused (as
    # --gate-mm always was) before any file is read; with --subjects 2 it is accepted
    monkeypatch.chdir(tmp_path)
    argv = [*COMMANDS[command], option, str(GIVEN[option][1])]
    assert monet(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f'monet {command}: error: {option} applies only with --subjects N '
                   f'(N >= 2); monet {command} runs one subject without it')
    assert monet([*argv, '--subjects', '2']) == 2             # fails on the missing files
    assert 'applies only' not in capsys.readouterr().err
    # the default value typed out changes nothing, so it is not refused (as --gate-mm 400)
    default = str(getattr(TrackerConfig(), GIVEN[option][0]))
    assert monet([*COMMANDS[command], option, default]) == 2  # the missing files again
    assert 'applies only' not in capsys.readouterr().err
