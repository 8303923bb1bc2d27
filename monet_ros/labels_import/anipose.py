"""anipose 2D outputs: pose-2d/<video>.h5 per camera (DeepLabCut's prediction layout,
index = frame number, coords x, y, likelihood; camera = the recording camera whose name
the file name contains, as anipose's cam_regex does). Points below --min-score are left
out and counted."""
from monet_ros.labels_import.dlc import _files, import_dlc_files


def import_anipose(paths, cameras=(), camera=None, min_score=0.0, camera_map=None):
    files = []
    for p in paths:
        files += sorted(p.rglob('*.h5')) if p.is_dir() else [p]
    if not files:
        files = _files(paths, ('.h5', '.csv'))
    return import_dlc_files(files, cameras, camera, min_score, camera_map)
