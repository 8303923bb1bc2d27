"""Synthetic calibrated rig and articulated subject renderer (no ROS)."""
from monet_ros.synth.rig import RigConfig, RigConfigError, make_rig
from monet_ros.synth.subject import Subject, SubjectConfig, SubjectError

__all__ = ['make_rig', 'RigConfig', 'RigConfigError', 'Subject', 'SubjectConfig',
           'SubjectError']
