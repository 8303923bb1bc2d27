"""ament_python package: library, config/ and launch/ to share/, executables to lib/."""
from glob import glob
import os

from setuptools import find_packages, setup

PACKAGE = 'monet_ros'

# Executables run as `ros2 run monet_ros <name>`; setup.cfg puts them in lib/monet_ros.
EXECUTABLES = {
    'monet': 'monet_ros.entry:monet',   # exit-0 signal handlers before monet_ros.cli loads
    'detector': 'monet_ros.nodes.detector:main',
    'fusion': 'monet_ros.nodes.fusion:main',
    'player': 'monet_ros.nodes.player:main',
    'learner': 'monet_ros.nodes.learner:main',
}


def share_files(folder):
    """data_files entries that install `folder` (recursively) under share/monet_ros."""
    entries = []
    for path in sorted(glob(os.path.join(folder, '**', '*'), recursive=True)):
        if os.path.isfile(path):
            entries.append((os.path.join('share', PACKAGE, os.path.dirname(path)), [path]))
    return entries


setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*', 'bench']),
    # the `monet label` page: plain HTML / JS / CSS served from the package (no CDN)
    package_data={'monet_ros.label_app': ['static/*']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml']),
        *share_files('config'),
        *share_files('launch'),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='monet_ros developers',
    maintainer_email='dev@monet-ros.invalid',
    description='Live multi-camera 3D keypoint tracking after MONET (multiview semi-supervised '
                'keypoint detection).',
    license='BSD-3-Clause',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [f'{name} = {target}' for name, target in EXECUTABLES.items()],
    },
)
