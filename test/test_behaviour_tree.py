"""The py_trees baseline, tick by tick (tree status and blackboard per tick, as py_trees'
own tests do), and on the Figure 4 scenario through the study's step loop."""
import py_trees
import pytest
from py_trees.common import Status

from pearl_pomdp.interfaces import ObservingDecider
from pearl_sim.nursing_home import behaviour_tree as bt_module
from pearl_sim.nursing_home.behaviour_tree import PearlBehaviourTree, TickTimeout


@pytest.fixture()
def bt():
    return PearlBehaviourTree()


def step(bt, heard_after=None):
    """Tick once; return the action (and close its step with ``heard_after`` if given)."""
    action = bt.execute(None).action_name
    if heard_after is not None:
        bt.observe(action, heard_after)
    return action


def node(bt, name):
    return next(n for n in bt.root.iterate() if n.name == name)


def test_is_an_observing_decider(bt):
    assert isinstance(bt, ObservingDecider)


def test_contact_remind_confirm_guide_inform_tick_by_tick(bt):
    assert step(bt) == "DoNothing"
    assert bt.root.status == Status.RUNNING and bt.root.tip().name == "Idle"
    bt.observe("DoNothing", "g_physio")
    assert bt.snapshot()["pending"] == ["physio"]
    assert step(bt, "atRoom") == "GotoPatientRoom"
    assert bt.snapshot()["location"] == "room" and bt.snapshot()["contact"] is False
    assert step(bt, "unknown") == "RingDoorBell"              # nobody answered the first ring
    assert step(bt) == "RingDoorBell"                          # Retry: second ring
    assert node(bt, "Ring retry").status == Status.RUNNING and node(bt, "Ring retry").failures == 1
    bt.observe("RingDoorBell", "t_yes")
    assert step(bt, "yes") == "RemindPhysioAppt"
    assert bt.snapshot()["contact"] is True
    # A plain 'yes' to the reminder acknowledges it; the walk is offered (confirmed) next.
    assert step(bt, "t_yes") == "ConfirmGuideToPhysio"
    # Judged when its step closed: the answer is on the blackboard before the next tick.
    snap = bt.snapshot()
    assert snap["pending"] == [] and snap["walk_requested"] is True and snap["walk_offer"] is False
    assert step(bt, "atPhysio") == "GuideToPhysio"
    assert bt.snapshot()["contact"] is True                    # she followed the robot
    assert step(bt, "weather") == "TerminateGuidance"
    assert bt.snapshot()["guiding"] is False and bt.snapshot()["question"] == "weather"
    assert step(bt, "unknown") == "TellWeather"                # Inform pre-empts everything below
    quiet = [step(bt, "unknown") for _ in range(bt_module.QUIET_TICKS_BEFORE_HOME)]
    assert quiet == ["DoNothing"] * bt_module.QUIET_TICKS_BEFORE_HOME and bt.snapshot()["question"] is None
    assert bt.snapshot()["quiet"] == bt_module.QUIET_TICKS_BEFORE_HOME
    assert step(bt, "atHome") == "GoHome"
    assert step(bt) == "DoNothing" and bt.snapshot()["location"] == "home"


def test_preempted_reminder_still_counts_as_delivered(bt):
    """A t_go answer to the reminder makes Guide pre-empt the Remind leaf on the next tick;
    the delivery is recorded when the step closes, so the robot does not remind again."""
    bt.blackboard.location, bt.blackboard.contact = "room", True
    bt.observe("DoNothing", "g_physio")
    assert step(bt, "t_go") == "RemindPhysioAppt"
    assert bt.snapshot()["pending"] == []
    assert step(bt, "atPhysio") == "GuideToPhysio"
    assert step(bt, "yes") == "TerminateGuidance"
    assert step(bt, "unknown") == "DoNothing"


def test_unanswered_bell_backs_off_then_rings_again(bt):
    bt.observe("DoNothing", "g_physio")
    assert step(bt, "atRoom") == "GotoPatientRoom"
    rings = [step(bt, "unknown") for _ in range(bt_module.RING_ATTEMPTS)]
    assert rings == ["RingDoorBell"] * bt_module.RING_ATTEMPTS
    backoff = [step(bt, "unknown") for _ in range(bt_module.CONTACT_BACKOFF_TICKS)]
    assert backoff == ["DoNothing"] * bt_module.CONTACT_BACKOFF_TICKS
    assert step(bt) == "RingDoorBell"                          # the reminder is still pending


def test_spoken_go_is_confirmed_touch_go_is_not(bt):
    bt.blackboard.location, bt.blackboard.contact = "room", True
    bt.observe("DoNothing", "go")
    assert step(bt, "unknown") == "ConfirmGuideToPhysio"
    assert step(bt, "unknown") == "ConfirmGuideToPhysio"       # not understood: asked once more
    assert step(bt) == "DoNothing"                             # two unanswered: the offer is dropped
    assert bt.snapshot()["walk_offer"] is False
    bt.observe("DoNothing", "t_go")
    assert step(bt) == "GuideToPhysio"


def test_declined_walk_is_not_guided(bt):
    bt.blackboard.location, bt.blackboard.contact, bt.blackboard.walk_offer = "room", True, True
    assert step(bt, "no") == "ConfirmGuideToPhysio"
    assert step(bt) == "DoNothing" and bt.snapshot()["walk_requested"] is False


def test_stale_reannouncement_after_delivery_is_ignored(bt):
    bt.blackboard.location, bt.blackboard.contact = "room", True
    bt.observe("DoNothing", "g_vitamin")
    assert step(bt, "yes") == "RemindVitamin"
    assert step(bt, "g_vitamin") == "DoNothing"                # queued before the delivery: ignored
    assert bt.snapshot()["pending"] == []


def test_reset_clears_the_blackboard_and_tree(bt):
    bt.observe("DoNothing", "g_physio")
    step(bt)
    bt.reset()
    assert bt.snapshot()["pending"] == [] and bt.root.status == Status.INVALID
    assert step(bt) == "DoNothing"


def test_two_trees_do_not_share_a_blackboard():
    a, b = PearlBehaviourTree(), PearlBehaviourTree()
    a.observe("DoNothing", "g_physio")
    assert b.snapshot()["pending"] == [] and a.snapshot()["pending"] == ["physio"]


def test_tick_timeout_counts_ticks():
    child = py_trees.behaviours.Running(name="forever")
    timeout = TickTimeout("budget", child, ticks=2)
    statuses = []
    for _ in range(3):
        timeout.tick_once()
        statuses.append(timeout.status)
    assert statuses == [Status.RUNNING, Status.RUNNING, Status.FAILURE]


def test_figure4_completes_at_zero_noise():
    from pearl_sim.nursing_home.experiment import run_episode, with_word_error_rate
    from pearl_sim.nursing_home.scenario import default_domain, load_scenarios
    from pearl_pomdp.launch_xml import package_share_dir

    domain = default_domain()
    scenario = with_word_error_rate(load_scenarios(package_share_dir("pearl_pomdp") / "config" / "scenarios"
                                                   / "figure4.yaml")[0], 0.0)
    result = run_episode(scenario, PearlBehaviourTree(actions=list(domain.actions)), domain, seed=scenario.seed)
    assert result.guidance_completed and result.wrong_actions == 0
    assert result.goals_achieved == 3           # reminder, guidance, the weather question
    assert "TellWeather" in result.actions and result.actions.index("GuideToPhysio") < result.actions.index("TellWeather")


@pytest.mark.parametrize("reading", ["battery_low", "battery_ok"])
def test_a_battery_reading_that_closes_a_ring_is_not_her_answer(bt, reading):
    """The day domain's battery driver (docs/day.md, protocol 3) may close any step: the tree hears it as
    the robot's own reading, so a ring it closes made no contact and the tree rings again."""
    bt.observe("DoNothing", "g_physio")
    assert step(bt, "atRoom") == "GotoPatientRoom"
    assert step(bt, reading) == "RingDoorBell"
    assert bt.snapshot()["contact"] is False
    assert step(bt) == "RingDoorBell"                          # Retry: the ring was not answered
