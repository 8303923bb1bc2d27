"""bench/subjects_live.py on a few frames (4 cameras, no noise): the table's rows (1
subject; 2 and 3 with rival_peaks off and on); one subject, and 2 and 3 with rival_peaks,
are found with one identity each and exact 3D from the perfect heatmaps."""
import importlib.util


def test_the_live_bench_runs_and_finds_every_subject(repo_root, capsys, monkeypatch):
    monkeypatch.syspath_prepend(str(repo_root / 'bench'))
    spec = importlib.util.spec_from_file_location(
        'bench_subjects_live', repo_root / 'bench' / 'subjects_live.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.main(['--frames', '6', '--cameras', '4', '--noise', '0'])
    rows = [line.split('|')[1:-1] for line in capsys.readouterr().out.splitlines()
            if line.startswith('| ') and line[2].isdigit()]
    assert [(r[0].strip(), r[1].strip()) for r in rows] == [
        ('1', 'off'), ('2', 'off'), ('2', 'on'), ('3', 'off'), ('3', 'on')]
    # one subject, and several with rival_peaks: every subject with one identity, exact
    # (mm; without rival_peaks a hidden joint takes the neighbour's peak: not exact)
    for row in [rows[0], rows[2], rows[4]]:
        assert row[3].strip() == '0' and row[4].strip() == '1.000', row   # IDSW, IDF1
        assert all(float(e) < 0.1 for e in row[5].split(',')), row
