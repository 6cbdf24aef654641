"""Record, inspect and replay rosbag2 bags (MCAP, 'ros2' profile) — docs/design.md §8.

ROS-free (usable without rclpy): :mod:`.writer` (:class:`BagWriter`), :mod:`.reader`
(:class:`BagReader`, salvages truncated files), :mod:`.info`, :mod:`.msgdefs` (rosbag2's
message-definition text and RIHS01 hashes from the installed interface files),
:mod:`.metadata` (QoS profiles, ``metadata.yaml``), :mod:`.well_known` (the fixed strings).
The ROS side lives in the ROS layer: :mod:`pearl_pomdp.nodes.bag_recorder` (raw
subscriptions) and :mod:`pearl_pomdp.nodes.bag_replay` (bag inputs → belief tracker +
hierarchical policy under sim time).
"""
from pearl_pomdp.bags.metadata import QosProfile, TopicMetadata
from pearl_pomdp.bags.reader import BagError, BagMessage, BagReader, TopicInfo
from pearl_pomdp.bags.writer import BagWriter

__all__ = ["BagError", "BagMessage", "BagReader", "BagWriter", "QosProfile", "TopicInfo", "TopicMetadata"]
