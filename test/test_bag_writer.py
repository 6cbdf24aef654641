"""Bag writer/reader: every field round-trips; bytes equal rclpy's serializer; rosbags (an
independent implementation) reads our bags; metadata.yaml is rosbag2's v9 document."""
from __future__ import annotations

import json
import struct
from pathlib import Path

import pytest
import yaml

from pearl_pomdp.bags import msgdefs
from pearl_pomdp.bags import well_known as wk
from pearl_pomdp.bags.metadata import QosProfile, dump_yaml, parse_qos_list
from pearl_pomdp.bags.reader import BagError, BagReader
from pearl_pomdp.bags.writer import BagWriter
from pearl_pomdp.errors import PearlError

from rclpy import serialization as rclpy_serialization
from geometry_msgs.msg import PoseStamped  # noqa: E402
from std_msgs.msg import String  # noqa: E402

STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
TEXTS = ["what time is it", "give me the weather forecast for tomorrow", "größer — ça va ✓", ""]


def _pose(i: int) -> PoseStamped:
    m = PoseStamped()
    m.header.stamp.sec, m.header.stamp.nanosec = 100 + i, 250_000_000 * i
    m.header.frame_id = "map"
    m.pose.position.x, m.pose.position.y = 1.5 * i, -2.0
    m.pose.orientation.w = 1.0
    return m


def _write_sample(path: Path, **kw) -> dict:
    """A bag with 4 Strings and 3 PoseStamped; returns what was written."""
    latched = QosProfile(history="keep_last", depth=5, reliability="reliable", durability="transient_local")
    best = QosProfile(history="unknown", depth=0, reliability="best_effort", durability="volatile",
                      deadline=(1, 500), liveliness="manual_by_topic")
    written = []
    with BagWriter(path, custom_data={"scenario": "unit"}, **kw) as bag:
        bag.add_topic("/pearl/speech", "std_msgs/msg/String", qos=[QosProfile(), best])
        bag.add_topic("/pearl/nav_goal", "geometry_msgs/msg/PoseStamped", qos=[latched])
        t = 1_700_000_000_000_000_000
        for i, text in enumerate(TEXTS):
            data = rclpy_serialization.serialize_message(String(data=text))
            bag.write("/pearl/speech", data, t + 10 * i, publish_time=t + 10 * i - 3, sequence=40 + i)
            written.append(("/pearl/speech", t + 10 * i, t + 10 * i - 3, 40 + i, data))
            if i < 3:
                data = rclpy_serialization.serialize_message(_pose(i))
                bag.write("/pearl/nav_goal", data, t + 10 * i + 5)
                written.append(("/pearl/nav_goal", t + 10 * i + 5, t + 10 * i + 5, i + 1, data))
    return {"messages": written, "qos": {"/pearl/speech": [QosProfile(), best], "/pearl/nav_goal": [latched]}}


@pytest.mark.parametrize("kw", [{}, {"chunk_size": 256}, {"chunk_size": 4096, "compression": "zstd"}],
                         ids=["unchunked", "chunked", "zstd"])
def test_round_trip_every_field(tmp_path, kw):
    sample = _write_sample(tmp_path / "b", **kw)
    bag = BagReader(tmp_path / "b", salvage=False)
    assert not bag.salvaged and bag.metadata_file is not None
    got = [(m.topic, m.log_time, m.publish_time, m.sequence, m.data) for m in bag.messages]
    assert got == sample["messages"]
    assert list(bag.topics) == ["/pearl/speech", "/pearl/nav_goal"]
    speech, goal = bag.topics["/pearl/speech"], bag.topics["/pearl/nav_goal"]
    assert (speech.type, speech.message_count, speech.serialization_format) == ("std_msgs/msg/String", 4, "cdr")
    assert (goal.type, goal.message_count) == ("geometry_msgs/msg/PoseStamped", 3)
    assert speech.offered_qos_profiles == sample["qos"]["/pearl/speech"]
    assert goal.offered_qos_profiles == sample["qos"]["/pearl/nav_goal"]
    assert speech.type_description_hash == STRING_HASH
    assert goal.type_description_hash == msgdefs.type_hash("geometry_msgs/msg/PoseStamped")
    assert speech.definition == msgdefs.message_definition("std_msgs/msg/String")
    assert bag.start_time == 1_700_000_000_000_000_000 and bag.duration == 30
    assert bag.library.startswith("pearl_pomdp")
    for m in bag.read_messages(["/pearl/speech"]):
        assert rclpy_serialization.deserialize_message(m.data, String).data in TEXTS


def test_cdr_bytes_equal_rclpy_and_mcap_ros2(tmp_path):
    """What the reader returns is byte-for-byte rclpy's serialisation (and mcap-ros2's encoding)."""
    from mcap_ros2._dynamic import generate_dynamic  # noqa: F401  (import check)
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    _write_sample(tmp_path / "b")
    mcap_file = tmp_path / "b" / "b_0.mcap"
    with open(mcap_file, "rb") as f:
        decoded = [(ch.topic, msg.data, dec) for _s, ch, msg, dec in
                   make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages()]
    speech = [d for d in decoded if d[0] == "/pearl/speech"]
    assert [d[2].data for d in speech] == TEXTS
    for _topic, raw, dec in speech:
        assert raw == rclpy_serialization.serialize_message(String(data=dec.data))
    goals = [d for d in decoded if d[0] == "/pearl/nav_goal"]
    for i, (_topic, raw, dec) in enumerate(goals):
        assert raw == rclpy_serialization.serialize_message(_pose(i))
        assert (dec.header.frame_id, dec.pose.position.x) == ("map", 1.5 * i)


def test_rosbags_reads_our_bag(tmp_path):
    """rosbags (independent reader) sees the same topics, types, hashes, QoS, times and bytes."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import Reader

    sample = _write_sample(tmp_path / "b", chunk_size=1024)
    with Reader(tmp_path / "b") as r:
        assert r.message_count == 7
        conns = {c.topic: c for c in r.connections}
        assert conns["/pearl/speech"].msgtype == "std_msgs/msg/String"
        assert conns["/pearl/speech"].digest == STRING_HASH
        qos = conns["/pearl/nav_goal"].ext.offered_qos_profiles[0]
        assert (qos.depth, qos.durability.name, qos.reliability.name) == (5, "TRANSIENT_LOCAL", "RELIABLE")
        raw = [(c.topic, t, d) for c, t, d in r.messages()]
    assert [(t, lt, d) for t, lt, _p, _s, d in sample["messages"]] == raw
    with AnyReader([tmp_path / "b" / "b_0.mcap"]) as ar:
        texts = [ar.deserialize(d, c.msgtype).data for c, _t, d in ar.messages() if c.topic == "/pearl/speech"]
    assert texts == TEXTS


def test_metadata_yaml_is_rosbag2_v9(tmp_path):
    _write_sample(tmp_path / "b")
    text = (tmp_path / "b" / "metadata.yaml").read_text()
    info = yaml.safe_load(text)["rosbag2_bagfile_information"]
    assert info["version"] == 9 and info["storage_identifier"] == "mcap" and info["ros_distro"] == "jazzy"
    assert info["relative_file_paths"] == ["b_0.mcap"]
    assert info["message_count"] == 7
    assert info["starting_time"] == {"nanoseconds_since_epoch": 1_700_000_000_000_000_000}
    assert info["duration"] == {"nanoseconds": 30}
    assert info["files"] == [{"path": "b_0.mcap", "starting_time": {"nanoseconds_since_epoch": 1_700_000_000_000_000_000},
                              "duration": {"nanoseconds": 30}, "message_count": 7}]
    assert info["custom_data"] == {"scenario": "unit"}
    assert (info["compression_format"], info["compression_mode"]) == ("", "")
    topics = {t["topic_metadata"]["name"]: t for t in info["topics_with_message_count"]}
    speech = topics["/pearl/speech"]
    assert speech["message_count"] == 4
    assert speech["topic_metadata"]["type_description_hash"] == STRING_HASH
    assert speech["topic_metadata"]["offered_qos_profiles"][1] == {
        "history": "unknown", "depth": 0, "reliability": "best_effort", "durability": "volatile",
        "deadline": {"sec": 1, "nsec": 500}, "lifespan": {"sec": 9223372036, "nsec": 854775807},
        "liveliness": "manual_by_topic", "liveliness_lease_duration": {"sec": 9223372036, "nsec": 854775807},
        "avoid_ros_namespace_conventions": False}
    # yaml-cpp's layout: key order as rosbag2 writes it, sequences indented under their key.
    keys = [line.split(":")[0].strip() for line in text.splitlines() if line.startswith("  ") and not line.startswith("   ")]
    assert keys == ["version", "storage_identifier", "duration", "starting_time", "message_count",
                    "topics_with_message_count", "compression_format", "compression_mode",
                    "relative_file_paths", "files", "custom_data", "ros_distro"]
    assert "    - topic_metadata:\n        name: /pearl/speech\n" in text
    assert not list((tmp_path / "b").glob(".*tmp*"))  # atomic write leaves no temporary file


def test_mcap_records_as_rosbag2_writes_them(tmp_path):
    from mcap.reader import make_reader

    _write_sample(tmp_path / "b")
    with open(tmp_path / "b" / "b_0.mcap", "rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        summary = reader.get_summary()
        meta = list(reader.iter_metadata())
    assert header.profile == "ros2"
    schemas = {s.name: s for s in summary.schemas.values()}
    assert schemas["std_msgs/msg/String"].encoding == "ros2msg"
    assert schemas["geometry_msgs/msg/PoseStamped"].data.decode() == msgdefs.message_definition(
        "geometry_msgs/msg/PoseStamped")
    ch = {c.topic: c for c in summary.channels.values()}
    assert ch["/pearl/speech"].message_encoding == "cdr"
    assert set(ch["/pearl/speech"].metadata) == {"offered_qos_profiles", "topic_type_hash"}
    assert ch["/pearl/speech"].metadata["topic_type_hash"] == STRING_HASH
    assert ch["/pearl/nav_goal"].metadata["offered_qos_profiles"].startswith("- history: keep_last\n  depth: 5\n")
    # one record at open (so a killed recording keeps custom_data), the final one at close
    assert [m.name for m in meta] == ["rosbag2", "rosbag2"]
    early = yaml.safe_load(meta[0].metadata["serialized_metadata"])
    assert early["message_count"] == 0 and early["custom_data"] == {"scenario": "unit"}
    inner = yaml.safe_load(meta[-1].metadata["serialized_metadata"])
    assert inner["message_count"] == 7 and inner["version"] == 9
    assert summary.statistics.message_count == 7


def test_message_definitions_match_rosbag2_text():
    """rosbag2's LocalMessageDefinitionSource output (sizes measured from a rosbag2 install's output)."""
    string = msgdefs.message_definition("std_msgs/msg/String")
    assert len(string.encode()) == 263 and string.endswith("string data\n")
    pose = msgdefs.message_definition("geometry_msgs/msg/PoseStamped")
    assert len(pose.encode()) == 1690
    sep = "\n" + "=" * 80 + "\nMSG: "
    # depth-first, each dependency once, std::set order within a file
    order = [chunk.split("\n", 1)[0] for chunk in pose.split(sep)[1:]]
    assert order == ["geometry_msgs/Pose", "geometry_msgs/Point", "geometry_msgs/Quaternion",
                     "std_msgs/Header", "builtin_interfaces/Time"]
    assert msgdefs.msg_dependencies("Header h\nint32[3] a\nfoo_msgs/Bar[] b\n# c d\nstring<=5 s\n", "p") == [
        "foo_msgs/Bar", "p/Header"]
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)
    for t in ("std_msgs/msg/String", "geometry_msgs/msg/PoseStamped", "rosgraph_msgs/msg/Clock"):
        assert msgdefs.type_hash(t) == ts.hash_rihs01(t)


def test_qos_yaml_round_trip_and_legacy_integers():
    profiles = [QosProfile(), QosProfile(history="keep_all", depth=0, durability="transient_local")]
    text = dump_yaml([p.to_dict() for p in profiles])
    assert parse_qos_list(text, "x") == profiles
    legacy = "- history: 1\n  depth: 7\n  reliability: 2\n  durability: 1\n  deadline: {sec: 0, nsec: 0}\n" \
             "  lifespan: {sec: 2147483647, nsec: 4294967295}\n  liveliness: 1\n" \
             "  liveliness_lease_duration: {sec: 0, nsec: 0}\n  avoid_ros_namespace_conventions: false\n"
    (q,) = parse_qos_list(legacy, "x")
    assert (q.history, q.depth, q.reliability, q.durability) == ("keep_last", 7, "best_effort", "transient_local")
    assert q.lifespan == wk.DURATION_INFINITE  # Foxy's Fast DDS "infinite" translated as rosbag2 does
    with pytest.raises(PearlError, match=r"where: offered_qos_profiles\[0\]: reliability: 'sometimes'"):
        parse_qos_list("- reliability: sometimes\n", "where")


def test_writer_refuses_bad_use(tmp_path):
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("x")
    with pytest.raises(PearlError, match="already exists"):
        BagWriter(tmp_path / "full")
    with BagWriter(tmp_path / "w") as bag:
        with pytest.raises(PearlError, match="topic /nope was not added"):
            bag.write("/nope", b"\x00\x01\x00\x00", 1)
        bag.add_topic("/a", "std_msgs/msg/String")
        with pytest.raises(PearlError, match="already registered as std_msgs/msg/String"):
            bag.add_topic("/a", "geometry_msgs/msg/PoseStamped")
        with pytest.raises(PearlError, match="negative timestamp"):
            bag.write("/a", b"\x00\x01\x00\x00", -5)
    with pytest.raises(PearlError, match="closed"):
        bag.write("/a", b"", 1)


def _mcap_bytes(tmp_path) -> bytes:
    _write_sample(tmp_path / "src")
    return (tmp_path / "src" / "src_0.mcap").read_bytes()


def test_truncated_file_salvage_and_strict_error(tmp_path):
    data = _mcap_bytes(tmp_path)
    reader_all = BagReader(tmp_path / "src")
    # walk the records to the 6th Message record and cut 10 bytes into it
    pos, seen, cut_at = 8, 0, None
    while pos < len(data):
        op, length = data[pos], struct.unpack_from("<Q", data, pos + 1)[0]
        if op == 0x05:
            seen += 1
            if seen == 6:
                cut_at = pos + 9 + 10
                break
        pos += 9 + length
    assert cut_at is not None
    bad = tmp_path / "cut.mcap"
    bad.write_bytes(data[:cut_at])
    salvaged = BagReader(bad)
    assert salvaged.salvaged and len(salvaged.messages) == 5
    assert [m.data for m in salvaged.messages] == [m.data for m in reader_all.messages[:5]]
    assert f"truncated at offset {pos} of {cut_at}: incomplete MESSAGE record" in salvaged.problems[0]
    with pytest.raises(BagError, match=rf"cut.mcap: truncated at offset {pos} of {cut_at}"):
        BagReader(bad, salvage=False)


def test_malformed_bags_name_file_and_problem(tmp_path):
    cases = {
        "notmcap.mcap": (b"hello world, not a bag", r"notmcap.mcap: offset 0: not an MCAP file"),
        "empty.mcap": (b"", r"empty.mcap: offset 0: file is empty"),
    }
    for name, (content, pattern) in cases.items():
        (tmp_path / name).write_bytes(content)
        with pytest.raises(BagError, match=pattern):
            BagReader(tmp_path / name)
    # a chunk whose bytes were damaged: CRC check names the offset
    chunky = tmp_path / "chunky"
    _write_sample(chunky, chunk_size=100000)
    raw = bytearray((chunky / "chunky_0.mcap").read_bytes())
    chunk_pos = raw.index(bytes([0x06]), 8)  # first chunk record (after the header)
    raw[chunk_pos + 120] ^= 0xFF
    (tmp_path / "damaged.mcap").write_bytes(bytes(raw))
    with pytest.raises(BagError, match=rf"damaged.mcap: offset {chunk_pos}: malformed record"):
        BagReader(tmp_path / "damaged.mcap")
    # wrong profile / encoding: a plain MCAP file from another tool
    from mcap.writer import Writer

    with open(tmp_path / "json.mcap", "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="t")
        sid = w.register_schema("x", "jsonschema", b"{}")
        w.register_channel("/j", "json", sid)
        w.finish()
    with pytest.raises(BagError, match=r"json.mcap: offset \d+: topic /j: message encoding 'json', expected 'cdr'"):
        BagReader(tmp_path / "json.mcap")
    (tmp_path / "badmeta").mkdir()
    (tmp_path / "badmeta" / "metadata.yaml").write_text("rosbag2_bagfile_information:\n  version: 9\n  storage_identifier: sqlite3\n")
    with pytest.raises(BagError, match=r"badmeta/metadata.yaml: storage_identifier: 'sqlite3' is not supported"):
        BagReader(tmp_path / "badmeta")


def test_cli_bag_info_text_and_json(tmp_path, capsys):
    from pearl_pomdp.cli import main

    _write_sample(tmp_path / "b")
    assert main(["bag-info", str(tmp_path / "b")]) == 0
    out = capsys.readouterr().out
    assert "Messages:          7" in out and "Storage id:        mcap" in out
    assert "Topic: /pearl/speech | Type: std_msgs/msg/String | Count: 4 | Serialization Format: cdr" in out
    assert "Duration:          0.000000030s" in out and "Salvaged" not in out
    import json

    assert main(["bag-info", str(tmp_path / "b"), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["message_count"] == 7 and info["salvaged"] is False and info["metadata_mismatch"] == []
    assert {t["name"]: t["count"] for t in info["topics"]} == {"/pearl/speech": 4, "/pearl/nav_goal": 3}
    assert main(["bag-info", str(tmp_path / "missing")]) == 2
    assert "missing: no such bag" in capsys.readouterr().err


@pytest.mark.parametrize("version", [8, 9])
def test_reads_rosbag2_bag_from_another_writer(tmp_path, version):
    """A rosbag2 bag written by rosbags (chunked MCAP, its own metadata.yaml; QoS as integers
    in v8 and as names in v9) reads back with topics, QoS, times and bytes."""
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    inf = QosTime(sec=9223372036, nsec=854775807)
    qos = Qos(QosHistory.KEEP_LAST, 7, QosReliability.BEST_EFFORT, QosDurability.TRANSIENT_LOCAL, inf, inf,
              QosLiveliness.AUTOMATIC, inf, False)
    store = get_typestore(Stores.ROS2_JAZZY)
    path = tmp_path / f"other_v{version}"
    payloads = [rclpy_serialization.serialize_message(String(data=t)) for t in TEXTS]
    with Writer(path, version=version, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection("/pearl/speech", "std_msgs/msg/String", typestore=store, offered_qos_profiles=[qos])
        for i, data in enumerate(payloads):
            w.write(conn, 5_000 + i, data)
    bag = BagReader(path, salvage=False)
    assert [m.data for m in bag.messages] == payloads
    assert [m.log_time for m in bag.messages] == [5_000, 5_001, 5_002, 5_003]
    info = bag.topics["/pearl/speech"]
    assert info.type == "std_msgs/msg/String" and info.message_count == 4
    (q,) = info.offered_qos_profiles
    assert (q.history, q.depth, q.reliability, q.durability) == ("keep_last", 7, "best_effort", "transient_local")
    assert bag.metadata["version"] == version and bag.library.startswith("rosbags")
    from pearl_pomdp.bags.info import bag_info

    summary = bag_info(bag)
    assert summary["metadata_mismatch"] == [] and summary["message_count"] == 4 and not summary["salvaged"]


def test_recorded_scenarios_read_by_rosbags_and_mcap_ros2():
    """The bags in bags/ (recorded live by `pearl record`) decode with both independent readers."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader

    repo = Path(__file__).resolve().parents[1]
    bags = sorted(p for p in (repo / "bags").iterdir() if (p / "metadata.yaml").is_file())
    assert len(bags) >= 2
    for bag in bags:
        ours = BagReader(bag, salvage=False)
        with AnyReader([bag]) as ar:
            theirs = [(c.topic, t, bytes(d)) for c, t, d in ar.messages()]
            actions = [ar.deserialize(d, c.msgtype).name for c, _t, d in ar.messages() if c.topic == "/pearl/action"]
        assert sorted(theirs) == sorted((m.topic, m.log_time, m.data) for m in ours.messages)
        assert actions == json.loads((repo / "bags" / f"{bag.name}.expected.json").read_text())["expected_actions"]
        with open(next(bag.glob("*.mcap")), "rb") as f:
            decoded = sum(1 for _ in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages())
        assert decoded == ours.message_count


HOUR = 3_600_000_000_000


def _write_day(path: Path, max_duration_ns=HOUR) -> list:
    """Strings every 10 minutes for 3 h 30 min, in a bag split by the hour."""
    written = []
    with BagWriter(path, max_duration_ns=max_duration_ns) as bag:
        bag.add_topic("/pearl/speech", "std_msgs/msg/String", qos=[QosProfile()])
        for i in range(22):
            data = rclpy_serialization.serialize_message(String(data=f"minute {10 * i}"))
            bag.write("/pearl/speech", data, i * 600_000_000_000)
            written.append(("/pearl/speech", i * 600_000_000_000, data))
    return written


def test_a_bag_split_by_the_hour_is_whole_in_every_file_and_reads_back_in_order(tmp_path):
    from mcap.reader import make_reader
    from rosbags.rosbag2 import Reader

    written = _write_day(tmp_path / "day")
    files = sorted((tmp_path / "day").glob("*.mcap"), key=lambda p: int(p.stem.rsplit("_", 1)[1]))
    assert [f.name for f in files] == [f"day_{k}.mcap" for k in range(4)]
    # Each file is a finished MCAP file on its own (summary + footer) with its own schema and channel.
    per_file = []
    for f in files:
        with open(f, "rb") as fh:
            reader = make_reader(fh)
            summary = reader.get_summary()
            assert summary is not None and [c.topic for c in summary.channels.values()] == ["/pearl/speech"]
            per_file.append([m.log_time for _s, _c, m in reader.iter_messages()])
    assert [len(t) for t in per_file] == [6, 6, 6, 4]
    assert all(t[-1] - t[0] < HOUR for t in per_file)
    meta = yaml.safe_load((tmp_path / "day" / wk.METADATA_FILENAME).read_text())["rosbag2_bagfile_information"]
    assert meta["relative_file_paths"] == [f.name for f in files] and meta["message_count"] == 22
    assert [f["message_count"] for f in meta["files"]] == [6, 6, 6, 4]
    got = [(m.topic, m.log_time, m.data) for m in BagReader(tmp_path / "day").messages]
    assert got == written
    with Reader(tmp_path / "day") as r:                       # an independent reader agrees
        assert r.message_count == 22 and [t for _c, t, _d in r.messages()] == [w[1] for w in written]


def test_a_split_bag_without_its_metadata_reads_its_files_in_the_order_written(tmp_path):
    written = _write_day(tmp_path / "day", max_duration_ns=HOUR // 4)    # 11 files: day_10 after day_9
    (tmp_path / "day" / wk.METADATA_FILENAME).unlink()                     # as a killed recorder leaves it
    assert len(list((tmp_path / "day").glob("*.mcap"))) == 11
    assert [(m.topic, m.log_time, m.data) for m in BagReader(tmp_path / "day").messages] == written


def test_a_split_bag_refuses_a_duration_that_is_not_positive(tmp_path):
    with pytest.raises(PearlError, match="max_duration_ns 0"):
        BagWriter(tmp_path / "b", max_duration_ns=0)
