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


def test_a_figure_that_is_not_a_number_is_null_in_the_json_and_reads_back(tmp_path):
    """A mean of nothing (NaN) was written as the token NaN, not JSON: now null, and
    load_summaries gives NaN again."""
    import json
    nan = summary('supervised', 'rigA', 0.1)
    nan = EvalSummary('supervised', 'rigA', float('nan'), float('nan'), float('inf'), 2.0,
                      nan.pck, 5, {'seed': 1, 'px': float('nan')})
    paths = write_report(tmp_path, [nan])

    def refuse(token):
        raise ValueError(token)
    data = json.loads(paths['json'].read_text(), parse_constant=refuse)
    assert data[0]['reproj_mean_px'] is None and data[0]['gt_reproj_mean_px'] is None
    assert data[0]['extra'] == {'seed': 1, 'px': None}
    loaded, = load_summaries(paths['json'])
    assert np.isnan(loaded.reprojection_mean) and np.isnan(loaded.gt_reprojection_mean)
    assert loaded.gt_reprojection_std == 2.0
