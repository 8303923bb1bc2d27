"""The live pipeline on a full ROS 2 install: detector (all rig cameras, batched) + fusion,
and a player when `bag` is given, all in one namespace (default `monet`).

    ros2 launch monet_ros pipeline.launch.py rig:=/path/rig.yaml model:=/path/model.pt
    ros2 launch monet_ros pipeline.launch.py model:=CKPT bag:=REC        # rig = the recording
    ros2 launch monet_ros pipeline.launch.py model:=CKPT bag:=REC namespace:=rig1 \\
        transport:=compressed debug_image:=true use_sim_time:=true slop_ms:=5.0 rate:=0.5

Parameters come from config/{detector,fusion,player}.yaml, then these arguments. The player
waits until the detector subscribes to its image topics and the fusion node to the
heatmaps (player.yaml wait_for_subscribers / wait_for_subscribers_s, wait_for_topics) before
it plays. The Fast DDS profile
(config/fastdds_profile.xml, 64 MB shared memory) carries full-size images.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, SetEnvironmentVariable
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

from launch import LaunchDescription

# name -> (default, description) of the launch arguments
ARGUMENTS = {
    'bag': ('', 'recording to replay (rosbag2 folder or .mcap); empty: live cameras'),
    'rig': (LaunchConfiguration('bag'), 'rig file or recording of the cameras (default: bag)'),
    'model': (None, 'detector checkpoint (.pt)'),
    'namespace': ('monet', 'namespace of the nodes and their topics'),
    'transport': ('auto', 'image transport: auto (from the rig / recording), raw, compressed'),
    'debug_image': ('false', 'publish <cam>/debug_image (bgr8 source image with crop box, '
                    'peaks and fused keypoints)'),
    'use_sim_time': ('false', 'nodes follow /clock (the player publishes the bag time)'),
    'slop_ms': ('0.0', 'detector and fusion: stamp tolerance between cameras (ms)'),
    'rate': ('1.0', 'player: playback speed (0 = as fast as possible)'),
    'precision': ('auto', 'detector: network arithmetic, auto (bfloat16 where native, else '
                  'float32), float32 or bfloat16 (CPUs with AVX512-BF16 / AMX, CUDA)'),
    'backend': ('torch', 'detector: inference backend, torch or onnxruntime'),
    'device': ('', "detector: torch device ('' = CUDA when available, else CPU)"),
    'subjects': ('1', 'detector and fusion: most subjects tracked (>= 2: crop slots and the '
                 'keypoints3d subject field, docs/subjects.md; the player then waits '
                 'wait_for_subscribers_s for {camera}/heatmaps, which no node subscribes)'),
}


def generate_launch_description():
    config = os.path.join(get_package_share_directory('monet_ros'), 'config')
    arg = {name: LaunchConfiguration(name) for name in ARGUMENTS}
    sim_time = ParameterValue(arg['use_sim_time'], value_type=bool)
    declared = [DeclareLaunchArgument(name, description=text,
                                      **({} if default is None else {'default_value': default}))
                for name, (default, text) in ARGUMENTS.items()]
    common = dict(package='monet_ros', namespace=arg['namespace'], output='screen',
                  emulate_tty=True)
    return LaunchDescription(declared + [
        SetEnvironmentVariable('FASTRTPS_DEFAULT_PROFILES_FILE',
                               os.path.join(config, 'fastdds_profile.xml')),
        Node(executable='player', name='player', condition=IfCondition(
                 PythonExpression(["'", arg['bag'], "' != ''"])),
             parameters=[os.path.join(config, 'player.yaml'), {
                 'bag': ParameterValue(arg['bag'], value_type=str),
                 'wait_for_topics': ['{camera}/heatmaps'],      # the fusion node listens
                 'rate': ParameterValue(arg['rate'], value_type=float)}], **common),
        Node(executable='detector', name='detector',
             parameters=[os.path.join(config, 'detector.yaml'), {
                 'rig': ParameterValue(arg['rig'], value_type=str),
                 'model': ParameterValue(arg['model'], value_type=str),
                 'transport': ParameterValue(arg['transport'], value_type=str),
                 'debug_image': ParameterValue(arg['debug_image'], value_type=bool),
                 'precision': ParameterValue(arg['precision'], value_type=str),
                 'backend': ParameterValue(arg['backend'], value_type=str),
                 'device': ParameterValue(arg['device'], value_type=str),
                 'slop_ms': ParameterValue(arg['slop_ms'], value_type=float),
                 'subjects': ParameterValue(arg['subjects'], value_type=int),
                 'use_sim_time': sim_time}], **common),
        Node(executable='fusion', name='fusion',
             parameters=[os.path.join(config, 'fusion.yaml'), {
                 'rig': ParameterValue(arg['rig'], value_type=str),
                 'slop_ms': ParameterValue(arg['slop_ms'], value_type=float),
                 'subjects': ParameterValue(arg['subjects'], value_type=int),
                 'use_sim_time': sim_time}], **common),
    ])
