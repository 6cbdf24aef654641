"""`pearl replay`: every recorded scenario in bags/ reproduces its recorded actions.

The bags were recorded from the simulated world through the live nodes over DDS
(bags/record_scenarios.py, `pearl demo`); the replay feeds their inputs and /clock through the tracker and policy in one process under
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
import rclpy  # noqa: F401  (a missing install fails, it is not skipped)

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


#: The Figure 4 bag as shipped before the typed interfaces (issue 39): action, decision and speech as
#: std_msgs/String (JSON for the decision and the speech's confidence), the belief a Float64MultiArray
#: plus /pearl/belief_marginals; its domain snapshot declares the speech input a String.
BEFORE_TYPED = REPO / "test" / "data" / "bag_before_typed" / "figure4_guidance"


def test_the_shipped_bags_are_typed():
    for bag in BAGS:
        types = {t: i.type for t, i in BagReader(bag).topics.items()}
        assert (types["/pearl/action"], types["/pearl/belief"], types["/pearl/decision"], types["/pearl/speech"]) == (
            "pearl_interfaces/msg/Action", "pearl_interfaces/msg/Belief", "pearl_interfaces/msg/Decision",
            "pearl_interfaces/msg/RecognisedSpeech"), bag.name
    old = {t: i.type for t, i in BagReader(BEFORE_TYPED).topics.items()}
    assert (old["/pearl/action"], old["/pearl/belief"], old["/pearl/speech"]) == (
        "std_msgs/msg/String", "std_msgs/msg/Float64MultiArray", "std_msgs/msg/String")


@pytest.mark.parametrize("bag", [*BAGS, BEFORE_TYPED], ids=[*(b.name for b in BAGS), "before_typed"])
def test_replay_matches_recorded_actions(bag, tmp_path):
    """Every shipped bag, and one recorded before the typed interfaces: the same actions, the same beliefs."""
    configure_test_process(tmp_path)
    result = replay_bag(bag, domain_id=allocate_domain_id())
    expected = json.loads((bag.parent / f"{bag.name}.expected.json").read_text())["expected_actions"]
    assert result.expected_actions == expected  # what the bag holds is what was seen live
    assert result.actions == expected and result.match and result.first_mismatch is None
    # Parity: the tracker publishes the beliefs it published when the bag was recorded (b0 and one per step).
    assert result.expected_beliefs == len(expected) and result.beliefs == result.expected_beliefs
    assert result.beliefs_match and result.max_belief_difference <= 1e-12, result.max_belief_difference
    reader = BagReader(bag)
    inputs = sum(1 for m in reader.messages if m.topic.startswith("/pearl/") and
                 m.topic in ("/pearl/speech", "/pearl/touchscreen", "/pearl/laser", "/pearl/reminder"))
    # every input (and every silence, closed by the tracker's sim-time step timeout) closed
    # one step, and each step got one answer
    assert result.counters["updates"] == inputs + result.counters["timeouts"] == len(expected) - 1
    # the silences were closed by the tracker's step timeout, driven by the recorded /clock
    assert result.counters["timeouts"] >= 1
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


def _add_topic_as_recorded(out: BagWriter, topic) -> None:
    """``topic`` of a bag read (``TopicInfo``) registered in ``out`` with its recorded definition and hash."""
    out.add_topic(topic.name, topic.type, qos=topic.offered_qos_profiles, definition=topic.definition,
                  type_hash=topic.type_description_hash)


def _copy_bag(src: Path, dst: Path, *, action_override=None, custom=None, retype=None) -> Path:
    """Rewrite ``src`` to ``dst`` (absolute custom_data paths), optionally altering it."""
    from rclpy.serialization import serialize_message

    from pearl_pomdp.nodes import conversions as cv

    reader = BagReader(src)
    data = dict((reader.metadata or {}).get("custom_data") or {})
    for key in ("pearl.domain", "pearl.policy"):
        data[key] = str((src / data[key]).resolve())
    if custom is not None:
        data = custom
    with BagWriter(dst, custom_data=data) as out:
        for name, t in reader.topics.items():
            if name in (retype or {}):
                out.add_topic(name, retype[name], qos=t.offered_qos_profiles)
            else:   # as recorded: its definition says how to read its messages (an old Belief: complete)
                _add_topic_as_recorded(out, t)
        k = 0
        for m in reader.messages:
            payload = m.data
            if m.topic == "/pearl/action":
                if action_override and k in action_override:
                    payload = serialize_message(cv.action_to_msg(action_override[k]))
                k += 1
            out.write(m.topic, payload, m.log_time, m.publish_time, m.sequence)
    return dst


def _with_drive_progress(src: Path, dst: Path, at_s: float, distance: float) -> Path:
    """``src`` (absolute custom_data paths) with one /pearl/drive_progress for GotoPatientRoom at ``at_s``
    (log time), ``distance`` metres from the room, in its place in the file."""
    from rclpy.serialization import serialize_message

    from pearl_pomdp.nodes import conversions as cv

    reader = BagReader(src)
    data = dict((reader.metadata or {}).get("custom_data") or {})
    for key in ("pearl.domain", "pearl.policy"):
        data[key] = str((src / data[key]).resolve())
    at_ns = int(at_s * 1e9)
    progress = serialize_message(cv.drive_progress_to_msg("GotoPatientRoom", "room", distance, distance / 0.5, at_s))
    with BagWriter(dst, custom_data=data) as out:
        for t in reader.topics.values():
            _add_topic_as_recorded(out, t)
        out.add_topic("/pearl/drive_progress", "pearl_interfaces/msg/DriveProgress")
        pending = True
        for m in reader.messages:
            if pending and m.log_time > at_ns:
                out.write("/pearl/drive_progress", progress, at_ns)
                pending = False
            out.write(m.topic, m.data, m.log_time, m.publish_time, m.sequence)
    return dst


def test_replay_feeds_recorded_drive_progress_to_the_tracker(tmp_path):
    """Figure 4's GotoPatientRoom opens at 5 s with a 62.5 s deadline (home → room, 15 m) and arrives at
    30 s. A recorded progress report at 6 s moves the deadline: 12 m left → 46 s, the replay still
    matches; 0.5 m left → 17.25 s, the drive closes with navFailed before the landmark and the replay
    departs from the recording at the next action."""
    configure_test_process(tmp_path)
    src = REPO / "bags" / "figure4_guidance"
    far = replay_bag(_with_drive_progress(src, tmp_path / "far", 6.0, 12.0), domain_id=allocate_domain_id())
    assert far.match and far.counters["drive_progress"] == 1 and far.counters["deadline_moves"] == 1
    assert far.counters["nav_failures"] == 0
    near = replay_bag(_with_drive_progress(src, tmp_path / "near", 6.0, 0.5), domain_id=allocate_domain_id())
    assert near.counters["drive_progress"] == 1 and near.counters["nav_failures"] == 1
    assert not near.match and near.first_mismatch == 2 and near.expected_actions[2] == "RingDoorBell"


def _as_pearl_record_writes_it(src: Path, dst: Path, published: bool, keep_paths: bool = True) -> Path:
    """``src`` without ``pearl.tracker_params`` (and, unless ``keep_paths``, without ``pearl.domain`` and
    ``pearl.policy``), as ``pearl record`` beside a launched graph writes it; with ``published``, the
    nodes' latched settings before the first message, as such a recorder gets them: the tracker's
    ``/belief_tracker/settings`` (the bag's tracker parameters) and the policy's
    ``/hierarchical_policy/settings`` (the domain and policy as absolute paths, autonomy full)."""
    from rclpy.serialization import serialize_message

    from pearl_pomdp.nodes import conversions as cv

    reader = BagReader(src)
    data = dict((reader.metadata or {}).get("custom_data") or {})
    for key in ("pearl.domain", "pearl.policy"):
        data[key] = str((src / data[key]).resolve())
    tracker = json.loads(data.pop("pearl.tracker_params"))
    policy = {"domain": data["pearl.domain"], "policy": data["pearl.policy"], "autonomy": "full",
              "confirm_categories": [""]}
    if not keep_paths:
        del data["pearl.domain"], data["pearl.policy"]
    with BagWriter(dst, custom_data=data) as out:
        for t in reader.topics.values():
            _add_topic_as_recorded(out, t)
        if published:
            first = reader.messages[0].log_time
            for node, values in (("belief_tracker", tracker), ("hierarchical_policy", policy)):
                out.add_topic(f"/{node}/settings", "rcl_interfaces/msg/ParameterEvent")
                out.write(f"/{node}/settings", serialize_message(cv.settings_to_msg(f"/{node}", values, 0.0)), first)
        for m in reader.messages:
            out.write(m.topic, m.data, m.log_time, m.publish_time, m.sequence)
    return dst


def test_a_bag_of_pearl_record_replays_with_the_settings_the_nodes_published(tmp_path):
    """A bag `pearl record` made beside a launched graph has no pearl.tracker_params, domain or policy: the
    replay takes the step rules and places the tracker published latched (its 8 s step timeout, the
    scenario's map) and the domain and policy the policy node published. Without the tracker's, it can
    only use the params file's 10 s and the silent steps close at other times; without either, it says
    what to pass."""
    configure_test_process(tmp_path)
    src = REPO / "bags" / "figure4_guidance"
    published = replay_bag(_as_pearl_record_writes_it(src, tmp_path / "published", True, keep_paths=False),
                           domain_id=allocate_domain_id())
    assert published.tracker_params_from == "belief_tracker/settings"
    assert published.match and published.beliefs_match and published.max_belief_difference == 0.0
    bare = replay_bag(_as_pearl_record_writes_it(src, tmp_path / "bare", False), domain_id=allocate_domain_id())
    assert bare.tracker_params_from == "defaults" and not bare.match
    with pytest.raises(PearlError, match=r"custom_data has no 'pearl.domain' and the policy node published none: "
                                         r"pass --domain to replay it"):
        replay_bag(_as_pearl_record_writes_it(src, tmp_path / "nothing", False, keep_paths=False),
                   domain_id=allocate_domain_id())


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
                                       r"replay needs pearl_interfaces/msg/Action or std_msgs/msg/String"):
        replay_bag(retyped)
    # no replay configuration
    bare = _copy_bag(src, tmp_path / "bare", custom={})
    with pytest.raises(PearlError, match=r"bare: custom_data has no 'pearl.domain' and the policy node published "
                                         r"none: pass --domain"):
        replay_bag(bare)
    shutil.rmtree(cut)


@pytest.mark.parametrize("name", ["table4_clarification", "figure4_guidance"])
def test_explain_says_why_for_every_step(name, tmp_path):
    """--explain: per step the input that closed it, the belief after it and the EXECUTE trace of the answer."""
    from pearl_pomdp.model.domain_yaml import load_domain

    configure_test_process(tmp_path)
    bag = REPO / "bags" / name
    result = replay_bag(bag, domain_id=allocate_domain_id(), explain=True)
    assert result.match and result.divergence is None
    steps = result.explanation
    # One entry per decision: b0's, then one per closed step; each decision is the replayed action.
    assert [s["decision"]["action"] for s in steps] == result.actions
    assert steps[0]["closed_by"] is None
    domain = load_domain(REPO / "bags" / "pearl" / "domain.yaml")
    for s in steps[1:]:
        c = s["closed_by"]
        assert c["symbol"] in domain.observations and c["input"] in ("speech", "touchscreen", "laser", "reminder",
                                                                       "timeout")
        assert set(s["belief"]) == set(domain.feature_names)
        assert all(0.0 <= p <= 1.0 for _, p in s["belief"].values())
        trace = s["decision"]["trace"]
        assert trace and trace[-1]["choice"] == s["decision"]["action"]   # root → … → the primitive
    assert any(s["closed_by"] and s["closed_by"]["input"] == "timeout" for s in steps) or name == "figure4_guidance"


def test_explain_shows_the_first_divergence(tmp_path, capsys):
    from pearl_pomdp.cli import main

    configure_test_process(tmp_path)
    src = REPO / "bags" / "table4_clarification"
    n_actions = BagReader(src).topics["/pearl/action"].message_count
    bag = _copy_bag(src, tmp_path / "altered", action_override={n_actions - 3: "RingDoorBell"})
    code = main(["replay", str(bag), "--json", "--explain", "--domain-id", str(allocate_domain_id())])
    out = json.loads(capsys.readouterr().out)
    assert code == 1
    d = out["divergence"]
    assert d["action_index"] == n_actions - 3 and d["recorded"] == "RingDoorBell" and d["replayed"] != "RingDoorBell"
    assert d["replayed_trace"][-1]["choice"] == d["replayed"] and d["closed_by"]["symbol"]
    code = main(["replay", str(bag), "--explain", "--domain-id", str(allocate_domain_id())])
    text = capsys.readouterr().out
    assert f"first divergence at action {n_actions - 3}" in text and "why:" in text
