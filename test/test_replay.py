"""`pearl replay`: every recorded scenario in bags/ reproduces its recorded actions.

The bags were recorded from the live multi-process graph (bags/record_scenarios.py); the
replay feeds their inputs and /clock through the tracker and policy in one process under
sim time. A bag whose recorded actions were altered must be reported as a mismatch, and a
damaged or wrong-typed bag as an error naming the file and what is wrong.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from ros_helpers import REPO, allocate_domain_id, configure_test_process

pytestmark = pytest.mark.ros
pytest.importorskip("rclpy")

from pearl_pomdp.bags.reader import BagError, BagReader  # noqa: E402
from pearl_pomdp.nodes.bag_replay import replay_bag  # noqa: E402
from pearl_pomdp.bags.writer import BagWriter  # noqa: E402
from pearl_pomdp.errors import PearlError  # noqa: E402

BAGS = sorted(p for p in (REPO / "bags").iterdir() if (p / "metadata.yaml").is_file())


def test_bags_hold_the_two_paper_scenarios():
    names = {b.name for b in BAGS}
    assert {"table4_clarification", "figure4_guidance"} <= names
    for b in BAGS:
        expected = json.loads((REPO / "bags" / f"{b.name}.expected.json").read_text())["expected_actions"]
        assert len(expected) >= 5


@pytest.mark.parametrize("bag", BAGS, ids=[b.name for b in BAGS])
def test_replay_matches_recorded_actions(bag, tmp_path):
    configure_test_process(tmp_path)
    result = replay_bag(bag, domain_id=allocate_domain_id())
    expected = json.loads((REPO / "bags" / f"{bag.name}.expected.json").read_text())["expected_actions"]
    assert result.expected_actions == expected  # what the bag holds is what was seen live
    assert result.actions == expected and result.match and result.first_mismatch is None
    reader = BagReader(bag)
    inputs = sum(1 for m in reader.messages if m.topic.startswith("/pearl/") and
                 m.topic in ("/pearl/speech", "/pearl/touchscreen", "/pearl/laser", "/pearl/reminder"))
    # every input (and every silence, closed by the tracker's sim-time step timeout) closed
    # one step, and each step got one answer
    assert result.counters["updates"] == inputs + result.counters["timeouts"] == len(expected) - 1
    if bag.name == "table4_clarification":
        assert result.counters["timeouts"] == 1  # the silence: /clock drove the tracker's timer
    assert result.messages == reader.message_count and result.messages_per_second > 0


def test_cli_replay_json(tmp_path, capsys):
    from pearl_pomdp.cli import main

    configure_test_process(tmp_path)
    bag = REPO / "bags" / "figure4_guidance"
    code = main(["replay", str(bag), "--json", "--domain-id", str(allocate_domain_id())])
    out = json.loads(capsys.readouterr().out)
    assert code == 0
    assert out["match"] is True and out["actions"] == out["expected_actions"]
    assert isinstance(out["actions"], list) and out["messages"] == BagReader(bag).message_count
    assert out["messages_per_second"] > 0


def _copy_bag(src: Path, dst: Path, *, action_override=None, custom=None, retype=None) -> Path:
    """Rewrite ``src`` to ``dst`` (absolute custom_data paths), optionally altering it."""
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    reader = BagReader(src)
    data = dict((reader.metadata or {}).get("custom_data") or {})
    for key in ("pearl.domain", "pearl.policy"):
        data[key] = str((src / data[key]).resolve())
    if custom is not None:
        data = custom
    with BagWriter(dst, custom_data=data) as out:
        for name, t in reader.topics.items():
            out.add_topic(name, (retype or {}).get(name, t.type), qos=t.offered_qos_profiles)
        k = 0
        for m in reader.messages:
            payload = m.data
            if m.topic == "/pearl/action":
                if action_override and k in action_override:
                    payload = serialize_message(String(data=action_override[k]))
                k += 1
            out.write(m.topic, payload, m.log_time, m.publish_time, m.sequence)
    return dst


def test_altered_recording_is_a_mismatch(tmp_path, capsys):
    from pearl_pomdp.cli import main

    configure_test_process(tmp_path)
    src = REPO / "bags" / "table4_clarification"
    original = BagReader(src)
    n_actions = original.topics["/pearl/action"].message_count
    bag = _copy_bag(src, tmp_path / "altered", action_override={n_actions - 3: "RingDoorBell"})
    code = main(["replay", str(bag), "--json", "--domain-id", str(allocate_domain_id())])
    out = json.loads(capsys.readouterr().out)
    assert code == 1 and out["match"] is False
    assert out["first_mismatch"] == n_actions - 3
    assert out["expected_actions"][n_actions - 3] == "RingDoorBell" != out["actions"][n_actions - 3]


def test_broken_bags_are_errors_naming_file_and_problem(tmp_path, capsys):
    from pearl_pomdp.cli import main

    src = REPO / "bags" / "figure4_guidance"
    # truncated: replay refuses (bag-info would salvage)
    cut = tmp_path / "cut"
    cut.mkdir()
    data = (src / "figure4_guidance_0.mcap").read_bytes()
    (cut / "cut_0.mcap").write_bytes(data[: len(data) // 2])
    assert main(["replay", str(cut)]) == 2
    err = capsys.readouterr().err
    assert "cut_0.mcap: truncated at offset" in err and "Traceback" not in err
    # wrong type on the action topic
    retyped = _copy_bag(src, tmp_path / "retyped", retype={"/pearl/action": "geometry_msgs/msg/PoseStamped"})
    with pytest.raises(BagError, match=r"retyped: topic /pearl/action: recorded as geometry_msgs/msg/PoseStamped, "
                                       r"replay needs std_msgs/msg/String"):
        replay_bag(retyped)
    # no replay configuration
    bare = _copy_bag(src, tmp_path / "bare", custom={})
    with pytest.raises(PearlError, match=r"bare: custom_data has no 'pearl.domain': pass --domain"):
        replay_bag(bare)
    shutil.rmtree(cut)
