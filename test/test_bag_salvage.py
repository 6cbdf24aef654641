"""A recorder killed with SIGKILL leaves a bag that bag-info reads (salvaged).

The recorder flushes every message to the file as it arrives (unchunked MCAP), so every
message on disk before the kill must come back, intact and in order, although the file has
no footer, no summary and no metadata.yaml.
"""
from __future__ import annotations

import json
import signal
import sys
import textwrap
from pathlib import Path

import pytest

from ros_helpers import Proc, allocate_domain_id, ros_env, wait_for

pytestmark = pytest.mark.ros
import rclpy  # noqa: F401  (a missing install fails, it is not skipped)

from pearl_pomdp.bags.reader import BagError, BagReader  # noqa: E402

PUBLISHER = textwrap.dedent("""
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String
    rclpy.init()
    node = rclpy.create_node("salvage_publisher")
    pub = node.create_publisher(String, "/pearl/speech", QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
    while pub.get_subscription_count() == 0:
        rclpy.spin_once(node, timeout_sec=0.02)
    i = 0
    try:
        while rclpy.ok():
            pub.publish(String(data=f"utterance {i}")); i += 1
            rclpy.spin_once(node, timeout_sec=0.005)
    except (KeyboardInterrupt, Exception):
        pass
""")


def _count(bag: Path) -> int:
    try:
        return BagReader(bag).message_count
    except BagError:
        return 0


def test_sigkilled_recorder_leaves_salvageable_bag(tmp_path, capsys):
    from rclpy.serialization import deserialize_message
    from std_msgs.msg import String

    domain_id = allocate_domain_id()
    env = ros_env(domain_id, tmp_path / "log")
    bag = tmp_path / "killed"
    pearl = str(Path(sys.executable).parent / "pearl")
    recorder = Proc([pearl, "record", str(bag), "--topics", "/pearl/speech", "--custom-data", "run=killed"],
                    env, tmp_path / "log", "recorder")
    publisher = Proc([sys.executable, "-c", PUBLISHER], env, tmp_path / "log", "publisher")
    try:
        # wait until messages are being written, then kill without warning
        assert wait_for(lambda: _count(bag) >= 30, 60), recorder.stderr() + publisher.stderr()
        on_disk_before = _count(bag)
        recorder.popen.send_signal(signal.SIGKILL)
        recorder.popen.wait(timeout=10)
    finally:
        recorder.stop()
        publisher.stop()
    assert recorder.popen.returncode == -signal.SIGKILL
    assert not (bag / "metadata.yaml").exists()

    from pearl_pomdp.cli import main

    assert main(["bag-info", str(bag), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["salvaged"] is True and info["metadata_yaml"] is False
    assert info["message_count"] >= on_disk_before  # everything flushed before the kill is there
    assert "truncated at offset" in info["problems"][0] and "killed_0.mcap" in info["problems"][0]
    assert info["topics"][0]["name"] == "/pearl/speech" and info["topics"][0]["count"] == info["message_count"]

    assert main(["bag-info", str(bag)]) == 0
    text = capsys.readouterr().out
    assert "Salvaged:" in text and "metadata.yaml:     missing" in text

    reader = BagReader(bag)
    numbers = [int(deserialize_message(m.data, String).data.split()[1]) for m in reader.messages]
    assert numbers == list(range(numbers[0], numbers[0] + len(numbers)))  # intact, in order, no gap
    assert [m.sequence for m in reader.messages] == [n + 1 for n in numbers]  # publisher sequence numbers

    # the strict reader (what replay uses) refuses the cut file, naming file and offset
    with pytest.raises(BagError, match=r"killed_0.mcap: truncated at offset \d+ of \d+"):
        BagReader(bag, salvage=False)

    # --repair rewrites it into a complete bag that every reader opens
    assert main(["bag-info", str(bag), "--repair", "--json"]) == 0
    repaired = json.loads(capsys.readouterr().out)
    assert repaired["salvaged"] is False and repaired["metadata_yaml"] is True
    assert repaired["message_count"] == len(numbers)
    assert (bag / "killed_0.mcap.broken").is_file() and (bag / "metadata.yaml").is_file()
    assert BagReader(bag).metadata["custom_data"] == {"run": "killed"}  # kept from the record written at open
    fixed = BagReader(bag, salvage=False)
    assert [m.data for m in fixed.messages] == [m.data for m in reader.messages]
    assert fixed.topics["/pearl/speech"].offered_qos_profiles == reader.topics["/pearl/speech"].offered_qos_profiles
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as ar:
        assert sum(1 for _ in ar.messages()) == len(numbers)
    assert main(["bag-info", str(bag), "--repair"]) == 2
    assert "complete; nothing to repair" in capsys.readouterr().err
