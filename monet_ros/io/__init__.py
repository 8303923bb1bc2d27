"""MCAP / rosbag2 reading and writing, ROS <-> numpy message conversion."""
