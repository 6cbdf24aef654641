"""A lost service answer (Fast DDS drops a server's answer when the client's response reader has
not matched in 100 ms) must not hang a test or repeat a transition: ``call_service`` re-sends a
repeatable request, ``transition`` reads the node's state instead. The servers here lose answers
on purpose, which DDS only does under load."""
from __future__ import annotations

import pytest

import ros_helpers
from ros_helpers import call_service

pytestmark = [pytest.mark.ros]   # the fakes hand out rclpy futures


class LosingClient:
    """A client whose server answers ``answer(request)`` but loses the first ``lost`` answers."""

    def __init__(self, srv_name, answer, lost=0):
        self.srv_name, self.answer, self.lost = srv_name, answer, lost
        self.sent, self.forgotten = [], []

    def service_is_ready(self):
        return True

    def call_async(self, request):
        from rclpy.task import Future   # what rclpy's Client.call_async returns

        self.sent.append(request)
        future = Future()
        result = self.answer(request)          # the server acts on every request that arrives
        if len(self.sent) > self.lost:
            future.set_result(result)
        return future

    def remove_pending_request(self, future):
        self.forgotten.append(future)


@pytest.fixture
def quick_resend(monkeypatch):
    monkeypatch.setattr(ros_helpers, "ANSWER_WAIT", 0.05)


def test_a_lost_answer_is_asked_for_again(quick_resend):
    client = LosingClient("/node/get_state", lambda request: f"answer to {request}", lost=2)
    assert call_service(client, "q", timeout=5.0) == "answer to q"
    assert client.sent == ["q", "q", "q"]
    assert len(client.forgotten) == 2          # the unanswered futures are dropped, not left pending


def test_a_service_that_never_answers_fails_naming_it(quick_resend):
    client = LosingClient("/node/get_state", lambda request: "never seen", lost=10 ** 9)
    with pytest.raises(AssertionError, match="/node/get_state did not answer in 0.3 s"):
        call_service(client, "q", timeout=0.3)
    assert len(client.sent) >= 2


class LifecycleNode:
    """Stands for a managed node: ChangeState moves ``label`` (its answers lost as asked), GetState reads it."""

    def __init__(self, label, lose_transition_answers):
        self.label, self.lose = label, lose_transition_answers
        self.transition_requests = 0

    def create_client(self, srv_type, name):
        from lifecycle_msgs.srv import ChangeState, GetState

        from test_lifecycle import TRANSITIONS

        if srv_type is ChangeState:
            def change(request):
                self.transition_requests += 1
                start, goal = TRANSITIONS[request.transition.id]
                ok = self.label == start
                if ok:
                    self.label = goal
                return ChangeState.Response(success=ok)
            return LosingClient(name, change, lost=10 ** 9 if self.lose else 0)

        def get(request):
            response = GetState.Response()
            response.current_state.label = self.label
            return response
        return LosingClient(name, get)

    def destroy_client(self, client):
        pass


def test_a_transition_whose_answer_is_lost_is_judged_by_the_state_it_reached(quick_resend):
    from lifecycle_msgs.msg import Transition

    import test_lifecycle

    node = LifecycleNode("unconfigured", lose_transition_answers=True)
    assert test_lifecycle.transition(node, None, "n", Transition.TRANSITION_CONFIGURE)
    assert node.label == "inactive" and node.transition_requests == 1     # asked once, never again
    assert test_lifecycle.transition(node, None, "n", Transition.TRANSITION_ACTIVATE)
    assert node.label == "active" and node.transition_requests == 2
    # Answered: the answer is the result, a refused transition included.
    answered = LifecycleNode("unconfigured", lose_transition_answers=False)
    assert not test_lifecycle.transition(answered, None, "n", Transition.TRANSITION_ACTIVATE)
    assert answered.label == "unconfigured"
