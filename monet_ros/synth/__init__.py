"""Synthetic calibrated rig and articulated subject renderer (no ROS).

synthesize(SynthConfig(...), out) writes a recording folder (see recording.py);
make_rig / Subject / Scene are the pieces.
"""
from monet_ros.synth.recording import SynthConfig, SynthError, synthesize
from monet_ros.synth.render import RenderConfig, Scene
from monet_ros.synth.rig import RigConfig, RigConfigError, make_rig
from monet_ros.synth.subject import Subject, SubjectConfig, SubjectError

__all__ = ['make_rig', 'RenderConfig', 'RigConfig', 'RigConfigError', 'Scene', 'Subject',
           'SubjectConfig', 'SubjectError', 'SynthConfig', 'SynthError', 'synthesize']
