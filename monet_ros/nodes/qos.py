"""QoS profiles shared by the nodes.

Inputs are best-effort (they match both reliable and best-effort publishers) and keep only
the newest messages, so a slow consumer drops old frames instead of queueing them.
Outputs are reliable (they match every subscriber). /monet/model is transient-local so a
late detector still receives the latest checkpoint announcement.
"""
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

# Camera images in: newest frame only (a slow detector drops, never queues).
IMAGE_IN = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                      reliability=ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.VOLATILE)
# Small per-frame messages in (heatmaps, camera_info, keypoints3d): a few frames of slack.
STREAM_IN = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                       reliability=ReliabilityPolicy.BEST_EFFORT,
                       durability=DurabilityPolicy.VOLATILE)
# Heatmaps + camera_info into fusion: best-effort so that reliable and best-effort detectors
# (another host's, anyone's) both match (with a reliable publisher on a healthy link nothing
# is lost in practice); deep enough to absorb a burst.
HEATMAPS_IN = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=30,
                         reliability=ReliabilityPolicy.BEST_EFFORT,
                         durability=DurabilityPolicy.VOLATILE)
# Everything we publish per frame.
STREAM_OUT = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                        reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE)
# Images we publish (player): reliable so that nothing is lost on a healthy link, shallow.
IMAGE_OUT = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=5,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)
# /monet/model and /tf_static: the latest value for late joiners.
LATCHED = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
