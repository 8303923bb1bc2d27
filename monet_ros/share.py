"""Where the package's data files are (config/, launch/): one rule for every caller.

From a source checkout (`pip install -e .`, tests, `python -m ...`) the files beside the
package are used; an installed package (colcon / `pip install --prefix`, no symlinks) finds
them in its share directory: the ament index (`AMENT_PREFIX_PATH`) when it knows the
package, else `<prefix>/share/monet_ros` of the prefix the package was installed into. No
ROS import (ament_index_python is optional), so the core may call it.
"""
import os
from pathlib import Path

PACKAGE = 'monet_ros'
_SOURCE_ROOT = Path(__file__).resolve().parent.parent


def _installed_share_dirs():
    """Candidate share/monet_ros directories of an installed package, best first."""
    try:
        from ament_index_python.packages import get_package_share_directory
        yield Path(get_package_share_directory(PACKAGE))
    except Exception:  # noqa: BLE001 - not installed / no ament_index_python: next rule
        pass
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if prefix:
            yield Path(prefix) / 'share' / PACKAGE
    # <prefix>/lib/pythonX.Y/site-packages/monet_ros -> <prefix>/share/monet_ros
    here = Path(__file__).resolve().parent
    for parent in here.parents:
        if (parent / 'share' / PACKAGE / 'package.xml').is_file():
            yield parent / 'share' / PACKAGE
            break


def share_path(*parts):
    """Path of a package data file or folder, e.g. share_path('config', 'fusion.yaml').

    The source checkout's copy when the package runs from one, else the installed share
    directory's. Raises FileNotFoundError naming every place looked at when neither has it.
    """
    source = _SOURCE_ROOT.joinpath(*parts)
    if source.exists() and (_SOURCE_ROOT / 'package.xml').is_file():
        return source
    looked = [source]
    for share in _installed_share_dirs():
        candidate = share.joinpath(*parts)
        if candidate.exists():
            return candidate
        looked.append(candidate)
    raise FileNotFoundError(f'{"/".join(parts)}: package data file not found (looked in '
                            f'{", ".join(str(p) for p in dict.fromkeys(looked))})')
