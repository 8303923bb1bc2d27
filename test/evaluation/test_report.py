"""Report tables in the paper's shape; Markdown, CSV, JSON round trip and the PCK plot."""
import csv

import numpy as np

from monet_ros.evaluation import EvalSummary, load_summaries, markdown_table, pck, write_report


def summary(mode, dataset, offset):
    result = pck(np.full((5, 3), offset), keypoints=('a', 'b', 'c'))
    return EvalSummary(mode, dataset, 3.0 + offset, 1.0, 4.0, 2.0, result, 5, {'seed': 1})


def test_table_rows_are_modes_in_paper_order_and_columns_datasets(tmp_path):
    summaries = [summary('monet', 'rigA', 0.04), summary('supervised', 'rigA', 0.15),
                 summary('supervised', 'rigB', 0.5)]
    text = markdown_table(summaries)
    lines = text.strip().splitlines()
    assert lines[0].startswith('| Mode | rigA reproj. (px)')
    assert 'rigB PCK@0.2' in lines[0]
    assert lines[2].startswith('| Supervised | 3.15 ± 1.00 | 4.00 ± 2.00 | 0.000 | 0.000 | 1.000')
    assert lines[3].startswith('| MONET | 3.04 ± 1.00')
    assert lines[3].endswith('| — | — | — | — | — |')   # monet has no rigB entry
    paths = write_report(tmp_path, summaries)
    with open(paths['csv']) as f:
        rows = list(csv.DictReader(f))
    assert [r['mode'] for r in rows] == ['monet', 'supervised', 'supervised']
    assert float(rows[0]['pck@0.05']) == 1.0 and float(rows[1]['pck@0.05']) == 0.0
    assert paths['pck_rigA'].stat().st_size > 1000
    assert paths['pck_rigA'].read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    loaded = load_summaries(paths['json'])
    assert loaded[1].mode == 'supervised'
    np.testing.assert_array_equal(loaded[1].pck.per_keypoint, summaries[1].pck.per_keypoint)
    assert loaded[0].extra == {'seed': 1}
