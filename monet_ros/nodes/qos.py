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
# (another host's, anyone's) both match; deep enough to absorb a burst. Fusion switches a
# topic to reliable once every publisher on it is reliable (adapted_reliability, as rosbag2
# does), so that a lost fragment of a large heatmap is sent again.
HEATMAPS_IN = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=30,
                         reliability=ReliabilityPolicy.BEST_EFFORT,
                         durability=DurabilityPolicy.VOLATILE)


def adapted_reliability(node, topic):
    """The reliability a subscription to `topic` should have to match every publisher on
    it with the best delivery: RELIABLE when all are reliable, BEST_EFFORT when any is
    best-effort, None when there is no publisher (yet)."""
    infos = node.get_publishers_info_by_topic(node.resolve_topic_name(topic))
    if not infos:
        return None
    if all(i.qos_profile.reliability == ReliabilityPolicy.RELIABLE for i in infos):
        return ReliabilityPolicy.RELIABLE
    return ReliabilityPolicy.BEST_EFFORT


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
