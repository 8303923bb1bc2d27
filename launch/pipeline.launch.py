"""The live pipeline on a full ROS 2 install: detector (all rig cameras, batched) + fusion,
and a player when `bag` is given.

    ros2 launch monet_ros pipeline.launch.py rig:=/path/rig.yaml model:=/path/model.pt
    ros2 launch monet_ros pipeline.launch.py rig:=REC model:=CKPT bag:=REC

Parameters come from config/{detector,fusion,player}.yaml, then these arguments. The Fast
DDS profile (config/fastdds_profile.xml, 64 MB shared memory) carries full-size images.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, SetEnvironmentVariable
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node

from launch import LaunchDescription


def generate_launch_description():
    share = get_package_share_directory('monet_ros')
    config = os.path.join(share, 'config')
    rig = LaunchConfiguration('rig')
    model = LaunchConfiguration('model')
    bag = LaunchConfiguration('bag')
    return LaunchDescription([
        DeclareLaunchArgument('rig', description='rig file (or recording) of the cameras'),
        DeclareLaunchArgument('model', description='detector checkpoint'),
        DeclareLaunchArgument('bag', default_value='', description='recording to replay'),
        SetEnvironmentVariable('FASTRTPS_DEFAULT_PROFILES_FILE',
                               os.path.join(config, 'fastdds_profile.xml')),
        Node(package='monet_ros', executable='player', name='player', output='screen',
             parameters=[os.path.join(config, 'player.yaml'), {'bag': bag}],
             condition=IfCondition(PythonExpression(["'", bag, "' != ''"]))),
        Node(package='monet_ros', executable='detector', name='detector', output='screen',
             parameters=[os.path.join(config, 'detector.yaml'), {'rig': rig, 'model': model}]),
        Node(package='monet_ros', executable='fusion', name='fusion', output='screen',
             parameters=[os.path.join(config, 'fusion.yaml'), {'rig': rig}]),
    ])
