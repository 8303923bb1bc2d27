"""Thin rclpy nodes: detector, fusion, learner, player."""
