"""An output folder a command makes as it starts (commands.common.made_output_dir: `monet
eval --out`, `monet process REC... --jobs N --out`) is removed again when the run fails or
is stopped before writing into it; a folder that existed before, or one holding results,
is kept."""
import pytest

from monet_ros.cli import main as monet
from monet_ros.commands.common import made_output_dir


def test_a_stopped_run_leaves_no_folder_it_made(tmp_path):
    out = tmp_path / 'a' / 'b' / 'out'
    with pytest.raises(KeyboardInterrupt):             # Ctrl-C / SIGTERM in a command
        with made_output_dir(out) as folder:
            assert folder == out and out.is_dir()
            raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []               # out, b and a: all made here


def test_a_folder_that_existed_or_holds_results_is_kept(tmp_path):
    kept = tmp_path / 'kept'
    kept.mkdir()
    with pytest.raises(KeyboardInterrupt), made_output_dir(kept):
        raise KeyboardInterrupt
    assert kept.is_dir()
    out = tmp_path / 'new' / 'out'
    with pytest.raises(ValueError), made_output_dir(out):
        (out / 'result.json').write_text('{}')
        raise ValueError('failed after writing')
    assert (out / 'result.json').is_file()
    with made_output_dir(tmp_path / 'done'):            # success: the folder stays
        pass
    assert (tmp_path / 'done').is_dir()


def test_monet_eval_refused_leaves_no_out_folder(tmp_path, capsys):
    out = tmp_path / 'eval'
    assert monet(['eval', '--out', str(out)]) == 2
    assert 'give checkpoints and --data' in capsys.readouterr().err
    assert not out.exists()
