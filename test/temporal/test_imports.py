"""The temporal layer imports neither ROS nor torch (numpy / scipy only)."""
import subprocess
import sys


def test_temporal_imports_no_rclpy_and_no_torch(repo_root):
    code = ('import sys, monet_ros.temporal; '
            "print(sorted(m for m in ('rclpy', 'torch') if m in sys.modules))")
    out = subprocess.run([sys.executable, '-c', code], cwd=repo_root, capture_output=True,
                         text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == '[]'
