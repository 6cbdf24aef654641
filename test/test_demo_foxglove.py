"""`pearl demo --foxglove`: a real WebSocket client connects to the demo's live view, gets the
advertised channels, subscribes, and receives belief marginals, actions, EXECUTE traces, the
transcript and the robot's pose while the episode runs through the ROS graph."""
from __future__ import annotations

import json
import re
import struct
import sys
import time
from pathlib import Path

import pytest

import foxglove  # noqa: F401  (a missing install fails, it is not skipped)
import websockets  # noqa: F401  (a missing install fails, it is not skipped)

from websockets.sync.client import connect  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ros_helpers import Proc, allocate_domain_id, ros_env  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
PEARL = Path(sys.executable).with_name("pearl")
pytestmark = pytest.mark.ros


def _url(proc: Proc, timeout: float = 30.0) -> str:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        m = re.search(r"live view on (ws://\S+)", proc.stderr())
        if m:
            return m.group(1)
        if proc.returncode is not None:
            break
        time.sleep(0.05)
    raise AssertionError(f"pearl demo printed no live-view URL:\n{proc.stderr()[-2000:]}")


def test_pearl_demo_foxglove_streams_the_episode(tmp_path):
    # The default domain and its shipped plan, as a user runs it.
    cmd = [str(PEARL), "demo", "--foxglove", "--foxglove-port", "0", "--foxglove-wait", "60", "--json",
           "--out", str(tmp_path / "out"), "--seed", "4",
           "--scenario", str(REPO / "config/scenarios/figure4.yaml")]
    proc = Proc(cmd, ros_env(allocate_domain_id(), tmp_path), tmp_path, "demo")
    try:
        url = _url(proc)
        with connect(url, subprotocols=["foxglove.sdk.v1"], open_timeout=10) as ws:
            channels = {}
            deadline = time.monotonic() + 10
            while len(channels) < 7 and time.monotonic() < deadline:
                text = json.loads(ws.recv(timeout=10))
                if text.get("op") == "advertise":
                    channels.update({c["topic"]: c for c in text["channels"]})
            assert {"/pearl/belief_marginals", "/pearl/action", "/pearl/decision", "/pearl/transcript",
                    "/pearl/pose", "/pearl/places", "/pearl/guide_pace"} <= set(channels)
            topic_of = {}
            subs = []
            for i, (topic, c) in enumerate(channels.items()):
                topic_of[i + 1] = topic
                subs.append({"id": i + 1, "channelId": c["id"]})
            ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
            got = {}
            deadline = time.monotonic() + 120
            while time.monotonic() < deadline and not ({"/pearl/belief_marginals", "/pearl/action",
                                                         "/pearl/decision", "/pearl/pose",
                                                         "/pearl/transcript"} <= set(got)
                                                        and len(got.get("/pearl/action", [])) >= 3):
                try:
                    frame = ws.recv(timeout=5)
                except TimeoutError:
                    if proc.returncode is not None:
                        break
                    continue
                if isinstance(frame, bytes) and frame[0] == 1:     # messageData
                    sub, _log_time = struct.unpack_from("<IQ", frame, 1)
                    got.setdefault(topic_of[sub], []).append(frame[13:])
        belief = json.loads(got["/pearl/belief_marginals"][-1])
        assert set(belief["marginals"]) >= {"UserLocation", "UserPresent"}
        assert abs(sum(belief["marginals"]["UserPresent"].values()) - 1.0) < 1e-9
        actions = [json.loads(a)["action"] for a in got["/pearl/action"]]
        assert actions[:2] == ["DoNothing", "GotoPatientRoom"]   # Figure 4 from b0: hear the reminder, drive to her
        decision = json.loads(got["/pearl/decision"][0])
        assert decision["trace"][-1]["choice"] == decision["action"]
        assert proc.wait(120) == 0, proc.stderr()[-3000:]
        summary = json.loads(proc.stdout())
        assert summary["actions"][:len(actions)] == actions[:len(summary["actions"])]
        assert "a Foxglove client subscribed; starting" in proc.stderr()
    finally:
        proc.stop()


def test_pearl_demo_foxglove_port_errors_are_one_line(tmp_path):
    proc = Proc([str(PEARL), "demo", "--foxglove", "--foxglove-port", "70000", "--out", str(tmp_path / "o")],
                ros_env(allocate_domain_id(), tmp_path), tmp_path, "bad")
    try:
        assert proc.wait(60) == 2
        assert "--foxglove-port 70000: not a TCP port (0-65535)" in proc.stderr()
    finally:
        proc.stop()
