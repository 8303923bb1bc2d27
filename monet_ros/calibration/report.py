"""The calibration report as a PNG (matplotlib, Agg backend; no ROS): detected-corner
coverage of each camera's image, each camera's reprojection-error histogram, and the rig
from above with the board poses."""
import numpy as np


def _top_view_axes(points):
    """2 orthonormal axes (2, 3) of the plane that best holds points (N, 3) (PCA): the
    view "from above" when cameras and boards spread horizontally."""
    centred = points - points.mean(axis=0)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    return vt[:2]


def write_report(path, result, corners, board):
    """Write the PNG report to path. corners: (C, F, N, 2) of every input camera."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    cams = result.cameras
    V = len(cams)
    fig = plt.figure(figsize=(4.2 * max(V, 2), 11.5))
    grid = fig.add_gridspec(3, max(V, 2), height_ratios=[1.0, 0.8, 1.4])
    obs = result.observations
    bins = np.linspace(0, max(1.0, float(np.percentile(result.errors, 99.5))), 40)
    for k, cam in enumerate(cams):
        c = result.names.index(cam.name)
        ax = fig.add_subplot(grid[0, k])
        pts = corners[c].reshape(-1, 2)
        pts = pts[np.isfinite(pts[:, 0])]
        ax.scatter(pts[:, 0], pts[:, 1], s=2, c='tab:blue', alpha=0.5)
        ax.set_xlim(0, cam.width)
        ax.set_ylim(cam.height, 0)
        ax.set_aspect('equal')
        ax.set_title(f'{cam.name}: {len(pts)} corners', fontsize=9)
        ax = fig.add_subplot(grid[1, k])
        errors = result.errors[obs.camera == c]
        ax.hist(errors, bins=bins, color='tab:orange')
        ax.set_xlabel('reprojection error (px)')
        ax.set_title(f'{cam.name}: mean {errors.mean():.2f} px, '
                     f'p95 {np.percentile(errors, 95):.2f} px', fontsize=9)
    ax = fig.add_subplot(grid[2, :])
    centres = np.stack([c.center for c in cams])
    poses = result.board_poses[np.isfinite(result.board_poses[:, 0, 0])]
    columns, rows = board.corner_grid
    outline = board.object_points[[0, columns - 1, columns * rows - 1, (rows - 1) * columns,
                                   0]]
    boards = np.einsum('fij,nj->fni', poses[:, :3, :3], outline) + poses[:, None, :3, 3]
    axes = _top_view_axes(np.concatenate([centres, boards.reshape(-1, 3)]))
    for b in boards:
        xy = b @ axes.T
        ax.plot(xy[:, 0], xy[:, 1], color='0.6', lw=0.8)
    scale = np.ptp(centres @ axes.T, axis=0).max() * 0.15 or board.square_length * 5
    for cam, centre in zip(cams, centres):
        tip = (centre + cam.R[2] * scale) @ axes.T
        xy = centre @ axes.T
        ax.plot(*xy, 'o', color='tab:red')
        ax.annotate('', tip, xy, arrowprops={'arrowstyle': '->', 'color': 'tab:red'})
        ax.text(xy[0], xy[1], f' {cam.name}', fontsize=9)
    ax.set_aspect('equal')
    ax.set_title(f'rig from above ({len(boards)} board poses, grey; board units)', fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
