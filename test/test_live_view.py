"""The Foxglove live view: a real WebSocket client (``websockets``) against ``LiveView``.

The client speaks the Foxglove WebSocket protocol: it receives ``serverInfo`` and the
``advertise`` of every channel, subscribes to all of them, and decodes the binary
``messageData`` frames (opcode 1, subscription id u32, log time u64, payload) the server
sends for a published belief, action, pose, transcript line and the places. The layout
file loads as JSON and every topic it shows is a channel of the live view.
"""
from __future__ import annotations

import json
import struct
import time
from pathlib import Path

import pytest

import foxglove  # noqa: F401  (a missing install fails, it is not skipped)
import websockets  # noqa: F401  (a missing install fails, it is not skipped)

from websockets.sync.client import connect  # noqa: E402

from pearl_pomdp.live_view import CHANNELS, LiveView  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
LAYOUT = REPO / "config" / "foxglove" / "pearl.layout.json"


def _receive(ws, until, timeout=5.0):
    out = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and not until(out):
        try:
            out.append(ws.recv(timeout=max(0.01, deadline - time.monotonic())))
        except TimeoutError:
            break
    return out


def test_a_client_gets_the_channels_and_the_belief_and_action_messages():
    with LiveView(port=0) as view, connect(view.url, subprotocols=["foxglove.sdk.v1"], open_timeout=10) as ws:
        texts = [json.loads(m) for m in _receive(ws, lambda got: sum(
            isinstance(m, str) and '"advertise"' in m for m in got) >= 1)]
        assert texts[0]["op"] == "serverInfo" and texts[0]["name"] == "pearl"
        channels = {c["topic"]: c for t in texts if t["op"] == "advertise" for c in t["channels"]}
        assert set(channels) == set(CHANNELS)
        assert channels["/pearl/belief_marginals"]["encoding"] == "json"
        assert channels["/pearl/pose"]["schemaName"] == "foxglove.PoseInFrame"
        assert channels["/pearl/transcript"]["schemaName"] == "foxglove.Log"
        subscription = {c["id"]: i + 1 for i, c in enumerate(channels.values())}
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": sub, "channelId": cid} for cid, sub in subscription.items()]}))
        topic_of = {subscription[c["id"]]: t for t, c in channels.items()}
        marginals = {"step": 3, "action": "GuideToPhysio", "observation": "atPhysio",
                     "marginals": {"UserLocation": {"room": 0.05, "physio": 0.95}}}
        # A subscription takes effect asynchronously: publish until the first frame arrives.
        frames = []
        deadline = time.monotonic() + 10
        while not frames and time.monotonic() < deadline:
            view.publish("/pearl/action", "GuideToPhysio", stamp_s=120.5)
            frames = [m for m in _receive(ws, lambda got: any(isinstance(m, bytes) for m in got), 0.2)
                      if isinstance(m, bytes)]
        assert frames, "no messageData frame for /pearl/action"
        view.publish("/pearl/belief_marginals", marginals, stamp_s=121.0)
        view.publish("/pearl/pose", {"x": 21.0, "y": -4.0, "yaw": 3.1}, stamp_s=121.0)
        view.publish("/pearl/transcript", {"speaker": "robot", "text": "Please follow me."}, stamp_s=121.0)
        view.publish_places({"home": [0.0, 0.0, 0.0], "physio": [21.0, -4.0, 3.1416]}, stamp_s=121.0)
        vetoed = {"event": "vetoed", "action": "GuideToPhysio", "step": 3, "stamp": 121.0, "autonomy": "confirm",
                  "detail": "re-decided without GuideToPhysio: ConfirmGuideToPhysio"}
        view.publish("/pearl/operator/events", vetoed, stamp_s=121.0)
        frames += [m for m in _receive(ws, lambda got: len([m for m in got if isinstance(m, bytes)]) >= 5)
                   if isinstance(m, bytes)]
    got = {}
    for frame in frames:
        op, sub, log_time = struct.unpack("<BIQ", frame[:13])
        assert op == 1
        got.setdefault(topic_of[sub], []).append((log_time, frame[13:]))
    assert json.loads(got["/pearl/action"][0][1]) == {"action": "GuideToPhysio"}
    assert got["/pearl/action"][0][0] == 120_500_000_000  # the time the caller gave (sim time)
    assert [json.loads(p) for _, p in got["/pearl/belief_marginals"]] == [marginals]
    for topic in ("/pearl/pose", "/pearl/transcript", "/pearl/places"):
        assert len(got[topic]) == 1 and got[topic][0][0] == 121_000_000_000
    assert b"Please follow me." in got["/pearl/transcript"][0][1]
    assert b"place/physio" in got["/pearl/places"][0][1]
    assert [json.loads(p) for _, p in got["/pearl/operator/events"]] == [vetoed]


def test_publish_names_the_problem():
    with LiveView(port=0) as view:
        with pytest.raises(KeyError, match="live view has no channel '/pearl/beleif'"):
            view.publish("/pearl/beleif", {})
        with pytest.raises(ValueError, match="live view /pearl/pose: value {'x': 1.0} lacks 'y'"):
            view.publish("/pearl/pose", {"x": 1.0})
        assert view.published["/pearl/pose"] == 0


def _leaves(node):
    if isinstance(node, str):
        return [node]
    return _leaves(node["first"]) + _leaves(node["second"])


def test_the_layout_shows_only_channels_of_the_live_view():
    layout = json.loads(LAYOUT.read_text())
    panels = layout["configById"]
    assert sorted(_leaves(layout["layout"])) == sorted(panels)
    topics = set()
    for config in panels.values():
        for key in ("topicPath", "topicToRender"):
            if key in config:
                topics.add(config[key])
        topics.update(config.get("topics", {}))
        topics.update("/" + p["value"].lstrip("/").split(".", 1)[0] for p in config.get("paths", []))
    assert topics == set(CHANNELS)
    # Plotted marginals name features and values of the Pearl domain.
    import yaml

    features = yaml.safe_load((REPO / "config" / "pearl.domain.yaml").read_text())["features"]
    for path in panels["Plot!belief"]["paths"]:
        _, _, feature, value = path["value"].split(".")
        assert value in [str(v) for v in features[feature]], path["value"]
