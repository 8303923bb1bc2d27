"""monet_ros: live multi-camera keypoint tracking with MONET (Yao, Jafarian, Park, ICCV 2019).

Core layers (geometry, models, learning, synth, evaluation) never import rclpy;
only `monet_ros.nodes` and `monet_ros.io` touch ROS messages.
"""

__version__ = '0.1.0'
