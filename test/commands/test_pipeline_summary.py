"""The live summary's last line: per-joint dropout, inlier views, and the plain statement
that reprojection error is agreement, not accuracy (bounded state: C counters)."""
from types import SimpleNamespace

import numpy as np

from monet_ros.commands.pipeline import Summary


def test_summary_reports_dropout_and_inlier_views():
    summary = Summary()
    summary.names = ['head', 'neck', 'hip']
    X = np.zeros((3, 3))
    for t in range(4):
        X_t = X.copy()
        if t < 3:
            X_t[2] = np.nan                          # hip dropped in 3 of 4 frames
        summary.on_fused(t, SimpleNamespace(X=X_t, reprojection_error=np.array([1.0, 2, 3]),
                                            num_views=np.array([4, 3, 2])))
    line = summary.line()
    # 9 of 12 joint-frames triangulated; inlier views (4*4 + 3*4 + 2*1) / 9
    assert 'joints triangulated 75% (most dropped: hip 75%)' in line
    assert f'mean inlier views {(16 + 12 + 2) / 9:.2f}' in line
    assert 'reprojection error is agreement between views, not accuracy' in line
    assert summary.joint_fused.tolist() == [4, 4, 1]


def test_summary_says_how_many_frames_fusion_skipped_as_stale():
    summary = Summary()
    summary.on_image('/cam0/image_raw', 1, 0.0)
    assert summary.line().startswith('frames 0 fused of 1 played') and 'stale' not in \
        summary.line()
    summary.stale_frames = lambda: 0
    assert 'stale' not in summary.line()
    summary.stale_frames = lambda: 1
    assert summary.line().startswith('frames 0 fused of 1 played (1 skipped as stale: '
                                     'fusion fell behind, max_queue_ms)')
