"""A file that is not a recording (a points CSV, random bytes, a text file named .mcap, an
MCAP cut before its first message) where a recording is expected: one line naming the file
and saying it is not an MCAP file, or not a complete one, exit 2, from every command that
opens a bag (the check is in io.open_bag)."""
from pathlib import Path

from helpers.commands import run_monet_process
from helpers.recordings import noise_recording, small_checkpoint

from monet_ros.cli import main as monet
from monet_ros.io import BagError, open_bag


def test_a_csv_given_as_recording_is_named_not_an_mcap_file(tmp_path, capsys):
    csv = tmp_path / 'two' / 'points2d.csv'
    csv.parent.mkdir()
    csv.write_text('stamp_ns,camera,keypoint,x,y,score\n1,cam0,nose,1.0,2.0,0.9\n')
    assert monet(['info', str(csv)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert str(csv) in err[0] and 'not an MCAP file' in err[0], err[0]
    assert 'CameraInfo' not in err[0]


def test_open_bag_refuses_a_non_mcap_file_and_a_cut_one_with_nothing_to_read(tmp_path):
    text = tmp_path / 'notes.txt'
    text.write_text('hello\n')
    try:
        open_bag(text)
    except BagError as error:
        assert str(text) in str(error) and 'not an MCAP file' in str(error)
    else:
        raise AssertionError('a text file opened as a bag')
    # a .mcap cut inside its magic holds nothing to read (one cut after some messages
    # is read as far as it parses: test/io/test_reader.py)
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(b'\x89MCAP0')
    try:
        open_bag(cut)
    except BagError as error:
        assert str(error) == (f'{cut} is not a complete MCAP file: no message can be read '
                              'from its 6 bytes (the file ends inside the MCAP magic; the '
                              'file is too short for a summary)')
    else:
        raise AssertionError('a 6-byte file opened as a bag')


def test_every_command_names_a_bag_with_nothing_to_read(tmp_path, repo_root):
    """`monet info / train / process / eval / pipeline --bag` on random bytes named .mcap,
    a text file named .mcap or a real recording cut inside its first chunk said 'no image
    topic for calibration camera cam0 ...' or 'has no CameraInfo topic; pass a rig file';
    each now exits 2 with open_bag's line (its last line: process says its precision
    first)."""
    noise_recording(tmp_path / 'rec', cameras=2, frames=2)
    whole = next((tmp_path / 'rec').glob('*.mcap')).read_bytes()
    model = small_checkpoint(tmp_path / 'model.pt')
    bags = {'cut.mcap': whole[:len(whole) // 3], 'noise.mcap': bytes(range(256)) * 64,
            'readme.mcap': b'# monet_ros\n' * 100}
    lines = {}
    for name, data in bags.items():
        (tmp_path / name).write_bytes(data)
        try:
            open_bag(tmp_path / name)
        except BagError as error:
            lines[name] = str(error)
    assert 'is not a complete MCAP file' in lines['cut.mcap']
    assert 'is not an MCAP file' in lines['noise.mcap'] and 'is not an MCAP file' in \
        lines['readme.mcap']
    bag = tmp_path / 'cut.mcap'
    runs = [('info', bag), ('train', bag, '--out', tmp_path / 'train', '--steps', 1),
            ('process', bag, '--model', model, '--out', tmp_path / 'p.mcap'),
            ('eval', model, '--data', bag, '--out', tmp_path / 'eval'),
            ('pipeline', '--bag', bag, '--model', model),
            ('info', tmp_path / 'noise.mcap'), ('info', tmp_path / 'readme.mcap')]
    for args in runs:
        result = run_monet_process(repo_root, *args, cwd=tmp_path)
        said = (result.stdout + result.stderr).strip().splitlines()
        assert result.returncode == 2, (args, said)
        line = lines[Path(args[args.index('--data') + 1] if '--data' in args else
                          args[args.index('--bag') + 1] if '--bag' in args else args[1]).name]
        assert said[-1] in (f'monet {args[0]}: {line}', f'monet {args[0]}: error: {line}'), \
            (args, said)
