"""`pearl record` against a live publisher process (own ROS_DOMAIN_ID), then read back.

The publisher waits until the recorder has matched, publishes 40 Strings and 8 PoseStamped
with known contents (TRANSIENT_LOCAL, so nothing falls into the discovery window), and
stays up; the recorder is stopped with SIGINT once the messages are on disk, and must
leave a complete bag: metadata.yaml, every message byte-identical to rclpy's serializer
(plus the wire's alignment padding), the publisher's QoS and type hash — readable by rosbags. SIGTERM closes as cleanly as SIGINT.
"""
from __future__ import annotations

import json
import signal
import sys
import textwrap
import time
from pathlib import Path

import pytest

from ros_helpers import REPO, Proc, allocate_domain_id, ros_env, wait_for

pytestmark = pytest.mark.ros
import rclpy  # noqa: F401  (a missing install fails, it is not skipped)

from pearl_pomdp.bags.reader import BagReader  # noqa: E402

N_TEXT, N_POSE = 40, 8

PUBLISHER = textwrap.dedent(f"""
    import time, rclpy
    from rclpy.qos import QoSProfile, DurabilityPolicy, ReliabilityPolicy
    from std_msgs.msg import String
    from geometry_msgs.msg import PoseStamped
    rclpy.init()
    node = rclpy.create_node("live_publisher")
    qos = QoSProfile(depth=64, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    speech = node.create_publisher(String, "/pearl/speech", qos)
    goal = node.create_publisher(PoseStamped, "/pearl/nav_goal", qos)
    while speech.get_subscription_count() == 0 or goal.get_subscription_count() == 0:
        rclpy.spin_once(node, timeout_sec=0.02)
    for i in range({N_TEXT}):
        speech.publish(String(data=f"what time is it, número {{i}}"))
    for i in range({N_POSE}):
        m = PoseStamped(); m.header.frame_id = "map"; m.pose.position.x = float(i); m.pose.orientation.w = 1.0
        goal.publish(m)
    print("published", flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, Exception):
        pass
""")


def _wire(cdr: bytes) -> bytes:
    return cdr + b"\0" * (-len(cdr) % 4)


def _messages_on_disk(bag) -> int:
    try:
        return BagReader(bag).message_count
    except Exception:
        return 0


@pytest.mark.parametrize("stop_signal", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_record_live_publisher_and_read_back(tmp_path, stop_signal):
    from geometry_msgs.msg import PoseStamped
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    domain_id = allocate_domain_id()
    env = ros_env(domain_id, tmp_path / "log")
    bag = tmp_path / "live"
    pearl = str(Path(sys.executable).parent / "pearl")
    recorder = Proc([pearl, "record", str(bag), "--topics", "/pearl/speech",
                     "/pearl/nav_goal", "--json"], env, tmp_path / "log", "recorder")
    publisher = Proc([sys.executable, "-c", PUBLISHER], env, tmp_path / "log", "publisher")
    try:
        assert wait_for(lambda: "published" in publisher.stdout(), 60), publisher.stderr() + recorder.stderr()
        assert wait_for(lambda: _messages_on_disk(bag) >= N_TEXT + N_POSE, 30), recorder.stderr()
        recorder.popen.send_signal(stop_signal)
        code = recorder.wait(15)
    finally:
        recorder.stop()
        publisher.stop()
    assert code == 0, recorder.stderr()
    summary = json.loads(recorder.stdout())
    assert summary["stopped_by"] == stop_signal.name and summary["messages"] == N_TEXT + N_POSE

    assert (bag / "metadata.yaml").is_file()
    reader = BagReader(bag, salvage=False)  # closed cleanly: footer, summary, metadata
    assert not reader.salvaged and reader.metadata_file is not None
    texts = [m for m in reader.messages if m.topic == "/pearl/speech"]
    poses = [m for m in reader.messages if m.topic == "/pearl/nav_goal"]
    # Raw bytes as on the wire: rclpy's serialization plus the zero padding Fast DDS adds
    # to a multiple of 4 bytes (recorded, like rosbag2, without re-serialising).
    assert [m.data for m in texts] == [_wire(serialize_message(String(data=f"what time is it, número {i}")))
                                       for i in range(N_TEXT)]
    expected_poses = []
    for i in range(N_POSE):
        p = PoseStamped()
        p.header.frame_id, p.pose.position.x, p.pose.orientation.w = "map", float(i), 1.0
        expected_poses.append(_wire(serialize_message(p)))
    assert [m.data for m in poses] == expected_poses
    assert [m.sequence for m in texts] == list(range(1, N_TEXT + 1))  # the publisher's sequence numbers
    assert all(m.publish_time <= m.log_time + 5_000_000_000 for m in reader.messages)
    assert abs(reader.start_time - time.time_ns()) < 600 * 1_000_000_000  # wall-clock stamps (no sim time)

    speech = reader.topics["/pearl/speech"]
    assert speech.type == "std_msgs/msg/String"
    assert speech.type_description_hash == "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
    (offered,) = speech.offered_qos_profiles
    assert (offered.reliability, offered.durability) == ("reliable", "transient_local")
    meta = reader.metadata
    assert meta["message_count"] == N_TEXT + N_POSE
    counts = {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]}
    assert counts == {"/pearl/speech": N_TEXT, "/pearl/nav_goal": N_POSE}

    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as ar:
        got = [ar.deserialize(d, c.msgtype).data for c, _t, d in ar.messages() if c.topic == "/pearl/speech"]
    assert got == [f"what time is it, número {i}" for i in range(N_TEXT)]


def test_record_refuses_existing_bag(tmp_path, capsys):
    from pearl_pomdp.cli import main

    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "metadata.yaml").write_text("x")
    assert main(["record", str(tmp_path / "old"), "--duration", "1"]) == 2
    assert "already exists" in capsys.readouterr().err
    assert main(["record", str(tmp_path / "new"), "--custom-data", "novalue"]) == 2
    assert "--custom-data: 'novalue' is not KEY=VALUE" in capsys.readouterr().err
    assert REPO.is_dir()
