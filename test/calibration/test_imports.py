"""The calibration layer imports neither ROS nor torch (DESIGN.md: core never imports rclpy)."""
import subprocess
import sys


def test_calibration_imports_no_rclpy_and_no_torch(repo_root):
    code = ('import sys, monet_ros.calibration.rig, monet_ros.calibration.report, '
            'monet_ros.calibration.summary, monet_ros.calibration.pairing; '
            "print(sorted(m for m in ('rclpy', 'torch') if m in sys.modules))")
    out = subprocess.run([sys.executable, '-c', code], cwd=repo_root, capture_output=True,
                         text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == '[]'
