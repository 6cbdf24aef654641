"""The reception behaviour tree's rules (pearl_sim/reception/behaviour_tree.py), step by step as its
docstring states them, and the tree in the reception world through the one step loop."""
from __future__ import annotations

from pathlib import Path

from pearl_sim.reception.behaviour_tree import ASK_ATTEMPTS, ASK_BACKOFF_TICKS, ReceptionBehaviourTree

REPO = Path(__file__).resolve().parents[1]


def _run(tree: ReceptionBehaviourTree, observations):
    """Tick, observe, tick …: the actions chosen after each observation (the first from the start)."""
    actions = [tree.execute().action_name]
    for symbol in observations:
        tree.observe(actions[-1], symbol)
        actions.append(tree.execute().action_name)
    return actions


def test_a_spoken_destination_is_confirmed_a_touched_one_is_not():
    tree = ReceptionBehaviourTree()
    assert _run(tree, ["charge_ok", "person_seen", "hello", "gallery", "yes", "at_gallery", "unheard", "at_desk"]) == [
        "Wait", "Wait", "Greet", "AskDestination", "ConfirmGallery", "EscortToGallery", "HandOver", "ReturnToDesk",
        "Wait"]
    tree.reset()
    assert _run(tree, ["person_seen", "t_office"]) == ["Wait", "Greet", "EscortToOffice"]


def test_a_no_forgets_the_destination_and_a_wrong_place_is_asked_again():
    tree = ReceptionBehaviourTree()
    assert _run(tree, ["person_seen", "hello", "office", "no"]) == [
        "Wait", "Greet", "AskDestination", "ConfirmOffice", "AskDestination"]
    tree.reset()
    # Handed over and told 'no': the destination is forgotten, the visitor is asked again.
    assert _run(tree, ["person_seen", "t_gallery", "at_gallery", "no"]) == [
        "Wait", "Greet", "EscortToGallery", "HandOver", "AskDestination"]


def test_two_unanswered_confirmations_go_and_three_unanswered_questions_back_off():
    tree = ReceptionBehaviourTree()
    assert _run(tree, ["person_seen", "hello", "gallery", "unheard", "unheard"])[-3:] == [
        "ConfirmGallery", "ConfirmGallery", "EscortToGallery"]
    tree.reset()
    asked = _run(tree, ["person_seen", "hello"] + ["unheard"] * (ASK_ATTEMPTS + ASK_BACKOFF_TICKS))
    assert asked[2:] == ["AskDestination"] * ASK_ATTEMPTS + ["Wait"] * ASK_BACKOFF_TICKS + ["AskDestination"]


def test_a_silent_greeting_is_a_passer_by_and_a_low_battery_docks_between_visitors():
    tree = ReceptionBehaviourTree()
    assert _run(tree, ["person_seen", "unheard", "charge_low", "at_desk", "charge_ok"]) == [
        "Wait", "Greet", "Wait", "Dock", "Wait", "Wait"]
    tree.reset()
    # With a visitor: the escort first, the dock after the hand-over.
    assert _run(tree, ["person_seen", "t_office", "charge_low", "at_office", "unheard"]) == [
        "Wait", "Greet", "EscortToOffice", "EscortToOffice", "HandOver", "Dock"]


def test_the_tree_serves_the_one_visitor_episode_through_the_step_loop():
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.reception.scenario import load_reception_scenarios
    from pearl_sim.reception.study import run_reception_episode

    domain = load_domain(REPO / "config/reception.domain.yaml")
    scenario = load_reception_scenarios(REPO / "config/scenarios/reception/study.yaml")[0]
    tree = ReceptionBehaviourTree("behaviour_tree", list(domain.compile().actions))
    episode = run_reception_episode(scenario, tree, domain, REPO / "config/reception_nodes.yaml", seed=101,
                                    word_error_rate=0.0)
    assert episode.success and episode.visitors_served == 1 and episode.steps == 40
    served = episode.actions.index("HandOver")
    assert episode.actions[served - 1] == "EscortToGallery" and "Greet" in episode.actions[:served]
