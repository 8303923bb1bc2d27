"""PCK curves (the paper's Figure 6) as PNG, with matplotlib's Agg backend (no display)."""
from pathlib import Path

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

from monet_ros.evaluation.report import MODE_ORDER, MODE_TITLES  # noqa: E402


def plot_pck_curves(summaries, path, title='PCK'):
    """One curve per summary (mode): overall PCK against the normalised threshold."""
    order = {m: i for i, m in enumerate(MODE_ORDER)}
    figure, axes = plt.subplots(figsize=(5.5, 4.0), dpi=110)
    for s in sorted(summaries, key=lambda s: order.get(s.mode, len(order))):
        axes.plot(s.pck.thresholds, s.pck.overall, marker='o', markersize=3,
                  label=MODE_TITLES.get(s.mode, s.mode))
    axes.set_xlabel('normalised distance (fraction of the ground-truth subject box side)')
    axes.set_ylabel('PCK')
    axes.set_ylim(0.0, 1.0)
    axes.set_xlim(0.0, 0.21)
    axes.grid(True, alpha=0.3)
    axes.set_title(title)
    axes.legend(loc='lower right', fontsize=8)
    figure.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path)
    plt.close(figure)
    return Path(path)
