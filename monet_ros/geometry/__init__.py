"""Multi-camera geometry: cameras, rig files, epipolar geometry, triangulation (no ROS)."""
