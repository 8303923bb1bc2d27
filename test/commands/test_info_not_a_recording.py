"""`monet info` given a file that is not a recording (a points CSV where a recording is
expected): one line naming the file and saying it is not an MCAP file, exit 2."""
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


def test_open_bag_refuses_a_non_mcap_file_but_reads_a_cut_mcap(tmp_path):
    text = tmp_path / 'notes.txt'
    text.write_text('hello\n')
    try:
        open_bag(text)
    except BagError as error:
        assert str(text) in str(error) and 'not an MCAP file' in str(error)
    else:
        raise AssertionError('a text file opened as a bag')
    # a damaged .mcap keeps being read as far as it parses (io.reader's loss reports)
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(b'\x89MCAP0')
    assert list(open_bag(cut).messages(decode=False)) == []
