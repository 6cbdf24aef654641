"""Strings and numbers that rosbag2 (Jazzy) and the MCAP 'ros2' profile fix.

Everything a bag must spell exactly as ``ros2 bag record -s mcap`` does lives here,
so the writer, the reader and the tests agree on one source:

* MCAP header profile ``ros2``; schema encoding ``ros2msg``; message encoding ``cdr``.
* Channel metadata keys ``offered_qos_profiles`` (a YAML list, rosbag2's v9 QoS form) and
  ``topic_type_hash`` (``RIHS01_…``).
* The MCAP metadata record ``rosbag2`` with the key ``serialized_metadata`` (the bag's
  ``metadata.yaml`` body, without its top-level key).
* ``metadata.yaml`` version 9 (Jazzy), storage identifier ``mcap``.
* QoS policies as rmw spells them (``keep_last``, ``reliable``, ``transient_local``, …);
  the integer values are rmw's enum values (used by metadata versions < 9).
"""
from __future__ import annotations

# --- MCAP -----------------------------------------------------------------------------
PROFILE = "ros2"
SCHEMA_ENCODING = "ros2msg"
SCHEMA_ENCODING_IDL = "ros2idl"
MESSAGE_ENCODING = "cdr"
CHANNEL_QOS_KEY = "offered_qos_profiles"
CHANNEL_TYPE_HASH_KEY = "topic_type_hash"
METADATA_RECORD_NAME = "rosbag2"
METADATA_RECORD_KEY = "serialized_metadata"
MCAP_SUFFIX = ".mcap"

# --- rosbag2 metadata.yaml ---------------------------------------------------------------
METADATA_FILENAME = "metadata.yaml"
METADATA_TOP_KEY = "rosbag2_bagfile_information"
METADATA_VERSION = 9
STORAGE_IDENTIFIER = "mcap"
ROS_DISTRO = "jazzy"
SERIALIZATION_FORMAT = "cdr"

# --- message definitions (rosbag2_cpp LocalMessageDefinitionSource) -----------------------
DEFINITION_SEPARATOR = "=" * 80
#: Field types of .msg files; rosbag2's regex, applied to the raw text (comments included).
MSG_FIELD_TYPE_PATTERN = r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+"
#: rosbag2_cpp's PRIMITIVE_TYPES: these are never dependencies.
PRIMITIVE_TYPES = frozenset(
    {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
     "int32", "uint32", "int64", "uint64", "string"}
)

# --- QoS (rmw) ---------------------------------------------------------------------------
#: rmw's names, indexed by the rmw enum value (what rclpy's QoS enums hold).
HISTORY_NAMES = {0: "system_default", 1: "keep_last", 2: "keep_all", 3: "unknown"}
RELIABILITY_NAMES = {0: "system_default", 1: "reliable", 2: "best_effort", 3: "unknown",
                     4: "best_available"}
DURABILITY_NAMES = {0: "system_default", 1: "transient_local", 2: "volatile", 3: "unknown",
                    4: "best_available"}
LIVELINESS_NAMES = {0: "system_default", 1: "automatic", 3: "manual_by_topic", 4: "unknown",
                    5: "best_available"}
#: RMW_DURATION_INFINITE as rosbag2 writes it: {sec: 9223372036, nsec: 854775807}.
DURATION_INFINITE = (9223372036, 854775807)

# --- topics of the Pearl graph (docs/design.md §6) ---------------------------------------------
CLOCK_TOPIC = "/clock"
CLOCK_TYPE = "rosgraph_msgs/msg/Clock"
STRING_TYPE = "std_msgs/msg/String"
