"""`monet process` prints the read report when the bag lost anything (issue 14, kind 3):
one record opcode of an image message flipped inside a chunk."""
import io

from helpers.mcap_layout import opcode_offsets
from helpers.recordings import noise_recording, small_checkpoint
from mcap.reader import make_reader

from monet_ros.cli import main as monet


def test_process_prints_the_report_of_a_damaged_bag(tmp_path, capsys):
    noise_recording(tmp_path / 'rec', cameras=2, frames=3)
    model = small_checkpoint(tmp_path / 'model.pt')
    bag = next((tmp_path / 'rec').rglob('*.mcap'))
    data = bytearray(bag.read_bytes())
    channels = make_reader(io.BytesIO(bytes(data))).get_summary().channels
    images = [o for o in opcode_offsets(bytes(data)) if data[o] == 0x05 and channels[
        int.from_bytes(data[o + 9:o + 11], 'little')].topic.endswith('image_raw')]
    data[images[-1]] ^= 0x10                       # the last image message: opcode 0x15
    bag.write_bytes(bytes(data))
    code = monet(['process', str(tmp_path / 'rec'), '--model', str(model), '--out',
                  str(tmp_path / 'out'), '--no-track', '--quiet'])
    err = capsys.readouterr().err
    assert code == 0, err
    assert f'reading {tmp_path / "rec"}' in err
    assert 'opcode 0x15' in err and 'could not be read' in err
