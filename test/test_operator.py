"""OperatorGate (ROS-free): autonomy levels, yes/no with a timeout, veto, command, bad input."""
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_veto import tiger  # noqa: E402

from pearl_pomdp.operator import OperatorGate
from pearl_pomdp.policies import FlatPolicyDecider
from pearl_pomdp.solvers.registry import solve

#: Tiger's actions tagged as a domain would: opening a door is the dangerous kind.
CATEGORIES = {"listen": "Sense", "open-left": "Door", "open-right": "Door"}
SURE_LEFT = np.array([0.97, 0.03])   # the policy opens the right door here


@pytest.fixture(scope="module")
def decider():
    model = tiger()
    return FlatPolicyDecider(solve(model, "incprune", horizon=8).policy, model)


def gate(decider, **kw):
    return OperatorGate(decider, decider.model.actions, CATEGORIES, **kw)


def kinds(out):
    return [e.kind for e in out.events]


def test_full_acts_at_once(decider):
    g = gate(decider)
    out = g.on_belief(SURE_LEFT, 1.0)
    assert out.publish == ["open-right"] and kinds(out) == ["acted"] and g.status == "acted"


def test_confirm_waits_for_yes_only_for_confirmed_categories(decider):
    g = gate(decider, autonomy="confirm", confirm_categories=["Door"], confirm_timeout=5.0)
    out = g.on_belief(np.array([0.5, 0.5]), 0.0)
    assert out.publish == ["listen"]                      # Sense is not confirmed
    out = g.on_belief(SURE_LEFT, 10.0)
    assert out.publish == [] and g.status == "waiting" and g.deadline() == 15.0
    assert g.proposal()["action"] == "open-right" and g.proposal()["status"] == "waiting"
    assert g.on_tick(14.9).events == []
    out = g.answer(True, 12.0)
    assert out.publish == ["open-right"] and kinds(out) == ["confirmed"] and g.deadline() is None
    assert g.answer(True, 12.5).error == "nothing is waiting for a confirmation"


def test_confirm_no_and_timeout_act_nothing(decider):
    g = gate(decider, autonomy="confirm", confirm_timeout=2.0)   # every action waits
    g.on_belief(SURE_LEFT, 0.0)
    out = g.answer(False, 1.0)
    assert out.publish == [] and kinds(out) == ["declined"] and g.status == "declined"
    g.on_belief(SURE_LEFT, 3.0)
    out = g.on_tick(5.0)
    assert out.publish == [] and kinds(out) == ["timeout"] and g.status == "timeout"
    assert g.answer(True, 6.0).error is not None        # too late: nothing acted
    # Handing over to full acts the step's decision now.
    out = g.set_level(7.0, autonomy="full")
    assert out.publish == ["open-right"] and kinds(out) == ["autonomy", "acted"]


def test_off_only_proposes(decider):
    g = gate(decider, autonomy="off")
    out = g.on_belief(SURE_LEFT, 0.0)
    assert out.publish == [] and kinds(out) == ["proposed"] and g.proposal()["status"] == "proposed"


def test_veto_re_decides_without_the_action_for_this_step_only(decider):
    g = gate(decider)
    g.on_belief(SURE_LEFT, 0.0)
    out = g.veto("open-right", 1.0)
    assert out.publish == [decider.execute_without(SURE_LEFT, ["open-right"]).action_name] == ["listen"]
    assert kinds(out) == ["vetoed", "acted"] and g.vetoed == {"open-right"}
    out = g.veto("open-left", 1.5)                       # not the choice: masked, nothing re-decided
    assert out.publish == [] and g.vetoed == {"open-right", "open-left"}
    out = g.veto("listen", 2.0)                          # every action vetoed: refused, nothing acted
    assert out.publish == [] and "every action is forbidden" in out.error and kinds(out) == ["rejected"]
    assert g.current == "listen" and g.vetoed == {"open-right", "open-left"}
    out = g.on_belief(SURE_LEFT, 3.0)                    # a new step: the vetoes are over
    assert out.publish == ["open-right"] and g.vetoed == set()


def test_veto_under_confirm_asks_again_for_the_new_choice(decider):
    g = gate(decider, autonomy="confirm", confirm_categories=["Door"])
    g.on_belief(np.array([0.03, 0.97]), 0.0)
    assert g.status == "waiting" and g.current == "open-left"
    out = g.veto("open-left", 1.0)
    assert out.publish == ["listen"] and g.status == "acted"


def test_command_is_published_at_any_level_and_withdraws_a_waiting_proposal(decider):
    g = gate(decider, autonomy="confirm")
    g.on_belief(SURE_LEFT, 0.0)
    out = g.command("listen", 1.0)
    assert out.publish == ["listen"] and kinds(out) == ["withdrawn", "commanded"] and g.source == "operator"
    g = gate(decider, autonomy="off")
    assert g.command("open-left", 0.0).publish == ["open-left"]


def test_bad_operator_input_is_refused_and_nothing_is_acted(decider):
    g = gate(decider)
    assert "nothing has been decided yet" in g.veto("listen", 0.0).error
    g.on_belief(SURE_LEFT, 0.0)
    for out in (g.veto("jump", 1.0), g.command("jump", 1.0)):
        assert out.publish == [] and "'jump' is not an action of the model" in out.error
        assert kinds(out) == ["rejected"]
    long = g.command("x" * 10_000, 1.0)
    assert long.publish == [] and len(long.error) < 200 and g.command("", 1.0).error.startswith("command refused: ''")
    with pytest.raises(ValueError, match="autonomy: 'half'"):
        g.set_level(2.0, autonomy="half")
    with pytest.raises(ValueError, match="confirm_categories: 'Drive' is not a category.*Door, Sense"):
        g.set_level(2.0, autonomy="confirm", confirm_categories=["Drive"])
    with pytest.raises(ValueError, match="confirm_timeout"):
        g.set_level(2.0, confirm_timeout=0.0)
    assert g.autonomy == "full"
