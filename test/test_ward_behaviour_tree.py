"""The ward's behaviour tree for several residents (pearl_sim/ward/behaviour_tree.py): each rule of its docstring."""
from pearl_sim.ward.behaviour_tree import ACTIONS, ROUND_STEPS, WardBehaviourTree


def _run(tree, observations):
    """Tick and observe in turn; the actions taken."""
    actions = []
    for obs in observations:
        a = tree.execute().action_name
        actions.append(a)
        tree.observe(a, obs)
    return actions


def test_the_trees_actions_are_the_ward_domains():
    from pearl_pomdp.model.domain_yaml import load_domain

    assert ACTIONS == list(load_domain("config/ward.domain.yaml").actions)


def test_a_call_is_answered_in_the_room_before_a_round():
    tree = WardBehaviourTree()
    first = tree.execute().action_name
    assert first == "GoToRoomAnn"                       # Ann's round is due at step 0
    tree.observe(first, "call_bob")                     # ... but Bob calls
    assert _run(tree, ["at_room_bob", "yes"]) == ["GoToRoomBob", "ServeBob"]
    assert tree.snapshot()["called"]["Bob"] is None and tree.snapshot()["need"]["Bob"] is None


def test_a_round_tries_the_room_then_the_lounge_then_waits_for_the_next_round():
    tree = WardBehaviourTree()
    acts = _run(tree, ["at_room_ann", "unheard", "at_lounge", "unheard"])
    assert acts == ["GoToRoomAnn", "RemindAnn", "GoToLounge", "RemindAnn"]
    snap = tree.snapshot()
    assert snap["round_due"]["Ann"] == 4 + ROUND_STEPS and not snap["round_tried"]["Ann"]


def test_a_need_heard_in_the_lounge_is_asked_resident_by_resident():
    tree = WardBehaviourTree()
    tree.blackboard.round_due = {"Ann": 99, "Bob": 99, "Cleo": 99}
    tree.blackboard.location = "lounge"
    tree.observe("Wait", "water")                       # someone in the lounge wants water: who?
    acts = _run(tree, ["no", "water", "yes"])
    assert acts == ["AskAnn", "AskBob", "ServeBob"]


def test_idle_it_goes_home_and_waits():
    tree = WardBehaviourTree()
    tree.blackboard.round_due = {"Ann": 99, "Bob": 99, "Cleo": 99}
    tree.blackboard.location = "lounge"
    assert _run(tree, ["at_station", "unheard"]) == ["GoToStation", "Wait"]
