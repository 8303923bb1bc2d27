"""The geometry layer imports neither ROS nor torch (fast start for nodes and tools)."""
import subprocess
import sys


def test_geometry_imports_no_rclpy_and_no_torch(repo_root):
    code = ('import sys, monet_ros.geometry, monet_ros.geometry.pose2sim; '
            "print(sorted(m for m in ('rclpy', 'torch') if m in sys.modules))")
    out = subprocess.run([sys.executable, '-c', code], cwd=repo_root, capture_output=True,
                         text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == '[]'
