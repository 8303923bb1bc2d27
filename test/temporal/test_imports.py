"""The temporal layer imports neither ROS nor torch (numpy / scipy only)."""
import subprocess
import sys

import pytest


@pytest.mark.parametrize('module', ['monet_ros.temporal', 'monet_ros.temporal.live'])
def test_temporal_imports_no_rclpy_and_no_torch(repo_root, module):
    code = (f'import sys, {module}; '
            "print(sorted(m for m in ('rclpy', 'torch') if m in sys.modules))")
    out = subprocess.run([sys.executable, '-c', code], cwd=repo_root, capture_output=True,
                         text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == '[]'
