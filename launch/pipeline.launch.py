"""The live pipeline on a full ROS 2 install: detector (all rig cameras, batched) + fusion,
and a player when `bag` is given, all in one namespace (default `monet`).

    ros2 launch monet_ros pipeline.launch.py rig:=/path/rig.yaml model:=/path/model.pt
    ros2 launch monet_ros pipeline.launch.py model:=CKPT bag:=REC        # rig = the recording
    ros2 launch monet_ros pipeline.launch.py model:=CKPT bag:=REC namespace:=rig1 \\
        transport:=compressed debug_image:=true use_sim_time:=true slop_ms:=5.0 rate:=0.5
    ros2 launch monet_ros pipeline.launch.py model:=CKPT bag:=REC subjects:=2 \\
        skeleton:=mouse6.yaml link_mm:=450.0                         # docs/subjects.md

Parameters come from config/{detector,fusion,player}.yaml, then these arguments (the
defaults of skeleton, link_mm and discovery_tiles are fusion.yaml's; discovery_tiles goes
to the detector too, so that the two nodes' discovery crop slots agree). The player waits
until the detector subscribes to its image topics and the fusion node to the heatmaps of
every camera (player.yaml wait_for_subscribers / wait_for_subscribers_s; wait_for_topics:
`<cam>/heatmaps`, with subjects N >= 2 the crop slots' `<cam>/crop<k>/heatmaps`, k <= N,
named by monet_ros.nodes.names as the nodes name them) before it plays. The Fast DDS profile
(config/fastdds_profile.xml, 64 MB shared memory) carries full-size images.
"""
import json
import os
from typing import List

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, SetEnvironmentVariable
from launch.conditions import IfCondition
from launch.substitution import Substitution
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch.substitutions.substitution_failure import SubstitutionFailure
from launch.utilities import normalize_to_list_of_substitutions, perform_substitutions
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
import yaml

from launch import LaunchDescription
from monet_ros.nodes.names import HEATMAPS, heatmap_sources

FUSION_YAML = object()    # default: the value in config/fusion.yaml

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
    'backend': ('auto', 'detector: inference backend, auto (onnxruntime for float32 on a '
                'CPU, torch for bfloat16 and on a GPU), torch or onnxruntime'),
    'device': ('', "detector: torch device ('' = CUDA when available, else CPU)"),
    'subjects': ('1', 'detector and fusion: most subjects tracked (>= 2: crop slots and the '
                 'keypoints3d subject field, docs/subjects.md; the player waits for the crop '
                 "slots' heatmap topics)"),
    'skeleton': (FUSION_YAML, 'fusion: skeleton preset or YAML path (heatmap channel order '
                 'and bones; default: config/fusion.yaml)'),
    'link_mm': (FUSION_YAML, 'fusion, subjects >= 2: largest distance (mm) between two linked '
                'keypoints of one subject (default: config/fusion.yaml)'),
    'discovery_tiles': (FUSION_YAML, 'detector and fusion, subjects >= 2: discovery tiles '
                        'along the shorter image side, one value for both nodes (they must '
                        'agree: the discovery crop slots; default: config/fusion.yaml)'),
}


class HeatmapTopics(Substitution):
    """The heatmap topics the fusion node subscribes for each camera, `{camera}` left for the
    player to fill (its wait_for_topics), as a YAML list: names.HEATMAPS of
    names.heatmap_sources for `subjects` (`{camera}/heatmaps` for 1, the crop slots'
    `{camera}/crop<k>/heatmaps`, k <= N, for N >= 2). Raises SubstitutionFailure when
    `subjects` is not an integer."""

    def __init__(self, subjects):
        super().__init__()
        self.subjects = normalize_to_list_of_substitutions(subjects)

    def describe(self):
        return f'HeatmapTopics(subjects={self.subjects})'

    def perform(self, context):
        text = perform_substitutions(context, self.subjects)
        try:
            subjects = int(text)
        except ValueError:
            raise SubstitutionFailure(f'launch argument subjects: {text!r} is not an '
                                      'integer') from None
        return json.dumps([HEATMAPS.format(camera=source)
                           for source in heatmap_sources('{camera}', subjects)])


def generate_launch_description():
    config = os.path.join(get_package_share_directory('monet_ros'), 'config')
    with open(os.path.join(config, 'fusion.yaml')) as f:
        fusion = yaml.safe_load(f)['/**/fusion']['ros__parameters']
    arg = {name: LaunchConfiguration(name) for name in ARGUMENTS}
    sim_time = ParameterValue(arg['use_sim_time'], value_type=bool)
    defaults = {name: str(fusion[name]) if default is FUSION_YAML else default
                for name, (default, _) in ARGUMENTS.items()}
    declared = [DeclareLaunchArgument(name, description=text, **(
                    {} if defaults[name] is None else {'default_value': defaults[name]}))
                for name, (_, text) in ARGUMENTS.items()]
    common = dict(package='monet_ros', namespace=arg['namespace'], output='screen',
                  emulate_tty=True)
    return LaunchDescription(declared + [
        SetEnvironmentVariable('FASTRTPS_DEFAULT_PROFILES_FILE',
                               os.path.join(config, 'fastdds_profile.xml')),
        Node(executable='player', name='player', condition=IfCondition(
                 PythonExpression(["'", arg['bag'], "' != ''"])),
             parameters=[os.path.join(config, 'player.yaml'), {
                 'bag': ParameterValue(arg['bag'], value_type=str),
                 # the fusion node listens (with subjects >= 2 to the crop slots)
                 'wait_for_topics': ParameterValue(HeatmapTopics(arg['subjects']),
                                                   value_type=List[str]),
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
                 'discovery_tiles': ParameterValue(arg['discovery_tiles'], value_type=int),
                 'use_sim_time': sim_time}], **common),
        Node(executable='fusion', name='fusion',
             parameters=[os.path.join(config, 'fusion.yaml'), {
                 'rig': ParameterValue(arg['rig'], value_type=str),
                 'slop_ms': ParameterValue(arg['slop_ms'], value_type=float),
                 'subjects': ParameterValue(arg['subjects'], value_type=int),
                 'skeleton': ParameterValue(arg['skeleton'], value_type=str),
                 'link_mm': ParameterValue(arg['link_mm'], value_type=float),
                 'discovery_tiles': ParameterValue(arg['discovery_tiles'], value_type=int),
                 'use_sim_time': sim_time}], **common),
    ])
