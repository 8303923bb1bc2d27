"""The stamp synchroniser of the fusion node: monet_ros.sync (one rule, live and offline)."""
from monet_ros.sync import Group, StampSynchronizer, SyncStats

__all__ = ['Group', 'StampSynchronizer', 'SyncStats']
