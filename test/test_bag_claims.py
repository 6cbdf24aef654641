"""bags/README.md's claims, checked against each bag's replay and the world's truth in it (issue 11).

The README's "Claims" list says what each recorded bag shows; this test parses it and checks
every claim against the actions the policy chooses when the bag is replayed (which must equal
the recorded ones) and the true state the simulator recorded on ``/pearl/sim/truth``. A bag
re-recorded after a domain change must either still show what the README says, or the README
must change with it.
"""
from __future__ import annotations

import re

import pytest

from ros_helpers import REPO, allocate_domain_id, configure_test_process

pytestmark = pytest.mark.ros
import rclpy  # noqa: F401  (a missing install fails, it is not skipped)

from pearl_pomdp.bags.reader import BagReader  # noqa: E402
from pearl_pomdp.nodes.bag_replay import replay_bag  # noqa: E402

README = REPO / "bags" / "README.md"
CLAIM = re.compile(r"^- `(?P<bag>[\w-]+)`: (?P<claim>.+)$")


def claims():
    text = README.read_text(encoding="utf-8")
    section = text.split("## Claims", 1)[1]
    out = [(m["bag"], m["claim"].strip()) for m in map(CLAIM.match, section.splitlines()) if m]
    assert out, "bags/README.md has no claims"
    return out


def truth(bag):
    """The world's truth records in ``bag`` (WorldTruth, or the JSON String of the bags recorded before it)."""
    from pearl_pomdp.world_truth import truth_records

    return truth_records(BagReader(bag), "/pearl/sim/truth")


def test_every_bag_in_the_table_has_claims_and_every_claim_a_bag():
    named = {bag for bag, _ in claims()}
    bags = {p.name for p in (REPO / "bags").iterdir() if (p / "metadata.yaml").is_file()}
    assert named == bags
    table = README.read_text(encoding="utf-8").split("## Claims", 1)[0]
    assert all(f"`{b}/`" in table for b in bags)


@pytest.fixture(scope="module")
def replays(tmp_path_factory):
    configure_test_process(tmp_path_factory.mktemp("replay"))
    out = {}
    for bag in sorted({b for b, _ in claims()}):
        result = replay_bag(REPO / "bags" / bag, domain_id=allocate_domain_id())
        assert result.match, f"{bag}: the replay differs from the recording at action {result.first_mismatch}"
        out[bag] = result.actions
    return out


@pytest.mark.parametrize("bag, claim", claims(), ids=[f"{b}: {c[:40]}" for b, c in claims()])
def test_claim_holds_in_the_replay(replays, bag, claim):
    actions = replays[bag]
    path = REPO / "bags" / bag
    if claim.startswith("in order "):
        wanted = [a.strip() for a in claim[len("in order "):].split(",")]
        it = iter(actions)
        missing = [a for a in wanted if not any(x == a for x in it)]
        assert not missing, f"{bag}: {wanted} not in order in {actions} (from {missing[0]})"
    elif claim.startswith("never "):
        assert claim[len("never "):].strip() not in actions
    elif claim == "rings only at her door":
        rings = [t["state"] for t in truth(path) if t.get("phase") == "start" and t.get("action") == "RingDoorBell"]
        assert rings, f"{bag}: no RingDoorBell"
        assert all(s["RobotLocation"] == s["UserLocation"] for s in rings), rings
    elif claim == "ends at home":
        final = truth(path)[-1]["state"]
        assert final["RobotLocation"] == "home", final
        assert "GoHome" in actions
    elif claim.startswith("answered "):
        answered = sum(e.endswith("question answered") for t in truth(path) for e in t.get("events") or [])
        assert answered == int(claim.split()[1])
    else:
        pytest.fail(f"bags/README.md: unknown claim {claim!r} for {bag}")
