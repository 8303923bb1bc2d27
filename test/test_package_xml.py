"""package.xml declares every ROS package the code imports, and every key resolves with
rosdep (checked by hand against ros/rosdistro at commit 8468e88 of 2026-08-22: ROS packages
in jazzy/distribution.yaml, system keys in rosdep/python.yaml)."""
import ast
from pathlib import Path
import xml.etree.ElementTree as ET

# ROS 2 Jazzy packages (jazzy/distribution.yaml release repositories' package lists).
JAZZY_PACKAGES = {
    'rclpy', 'rcl_interfaces', 'builtin_interfaces', 'rosgraph_msgs', 'sensor_msgs',
    'geometry_msgs', 'visualization_msgs', 'std_msgs', 'std_srvs', 'diagnostic_msgs',
    'tf2_msgs', 'ament_index_python', 'launch', 'launch_ros', 'ament_flake8',
}
# rosdep/python.yaml keys with a rule for Ubuntu (python3-pytorch-pip is a deprecated alias,
# python3-mcap-pip and python3-mcap-ros2-support-pip have no rule: not allowed here).
ROSDEP_RULES = {
    'python3-numpy', 'python3-opencv', 'python3-yaml', 'python3-scipy', 'python3-matplotlib',
    'python3-tqdm', 'python3-pytest', 'python3-torch', 'python3-rosbags-pip',
    # also checked at 8468e88: lab formats, the label app, the reliability and browser tests
    'python3-h5py', 'python3-pandas', 'python3-tables', 'python3-flask', 'python3-selenium',
    'python3-hypothesis',
    # checked at 8468e88: the compiled kernels (monet_ros.jit)
    'python3-numba',
}
# Keys the install guide's rosdep line (docs/install.md) skips (installed with a pinned pip
# line instead).
SKIPPED = {'python3-torch', 'python3-rosbags-pip'}
# Python import name -> the package.xml key that provides it.
THIRD_PARTY = {'numpy': 'python3-numpy', 'cv2': 'python3-opencv', 'yaml': 'python3-yaml',
               'scipy': 'python3-scipy', 'matplotlib': 'python3-matplotlib',
               'tqdm': 'python3-tqdm', 'torch': 'python3-torch',
               'rosbags': 'python3-rosbags-pip', 'h5py': 'python3-h5py',
               'pandas': 'python3-pandas', 'flask': 'python3-flask', 'numba': 'python3-numba'}


def declared(repo_root, tags=('exec_depend', 'depend', 'test_depend')):
    root = ET.parse(repo_root / 'package.xml').getroot()
    return {e.text.strip() for tag in tags for e in root.iter(tag)}


def imported_top_level(paths):
    names = set()
    for path in paths:
        for node in ast.walk(ast.parse(Path(path).read_text())):
            if isinstance(node, ast.Import):
                names.update(a.name.split('.')[0] for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                names.add(node.module.split('.')[0])
    return names


def test_every_key_resolves_with_rosdep(repo_root):
    keys = declared(repo_root)
    unknown = keys - JAZZY_PACKAGES - ROSDEP_RULES
    assert not unknown, f'keys without a rosdep rule or Jazzy package: {sorted(unknown)}'
    guide = (repo_root / 'docs' / 'install.md').read_text()
    assert f'--skip-keys "{" ".join(sorted(SKIPPED))}"' in guide


def test_every_imported_ros_package_is_declared(repo_root):
    sources = list((repo_root / 'monet_ros').rglob('*.py')) + \
        list((repo_root / 'launch').glob('*.py'))
    imported = imported_top_level(sources)
    ros = (imported & JAZZY_PACKAGES) | {THIRD_PARTY[n] for n in imported & set(THIRD_PARTY)}
    missing = ros - declared(repo_root, ('exec_depend', 'depend'))
    assert not missing, f'imported but not in package.xml: {sorted(missing)}'
    # and the ROS packages the nodes use at all are found by this scan
    assert {'rclpy', 'launch', 'launch_ros', 'tf2_msgs', 'ament_index_python',
            'rcl_interfaces'} <= imported
