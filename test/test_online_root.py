"""An online root over offline-planned children (docs/hierarchy.md, "Online root").

On the two-resident toy of ``test_separable_reward``: the root ``Care`` (``solver: online``) over
``CareA`` (planned offline: ask or serve A), ``ServeB`` and ``Wait``. DESPOT's choice at the root
must equal a brute-force search written here from the model's arrays — every root action, the
child resolved to what its policy picks at the exact successor belief, the search's own lower
bound at the leaves — at depth 1 and 2; the hierarchy file's errors name the field.
"""
import numpy as np
import pytest

from pearl_pomdp.errors import PolicyError, SpecError
from pearl_pomdp.hierarchy import load_hierarchical_policy, parse_hierarchy, plan
from pearl_pomdp.model.domain_yaml import parse_domain
from pearl_pomdp.online.despot import DespotSettings
from test_separable_reward import toy

HIERARCHY = """
root: Care
defaults: {solver: pointbased, trials: 30}
subtasks:
  Care: {actions: [CareA, ServeB, Wait], solver: online, trials: 40}
  CareA: {actions: [AskA, ServeA]}
"""


def _features(domain):
    return {f.name: list(f.values) for f in domain.features}


@pytest.fixture(scope="module")
def planned():
    domain = parse_domain(toy("no"))
    policy = plan(domain, parse_hierarchy(HIERARCHY, domain.actions, _features(domain)), seed=0)
    return domain, domain.compile(), policy


def _brute(policy, model, lower_alphas, b, depth):
    """Root Q-values ``[A_root]`` by exhaustive search: each root action resolved at ``b`` (a child: its
    policy's pick at the exact belief), leaves valued by the best lower-bound α-vector, inner nodes by
    ``max(leaf value, best action)`` as DESPOT's backup does."""
    root = policy.subtasks[policy.root]
    T = [np.asarray(t.toarray() if hasattr(t, "toarray") else t) for t in model.T]
    leaf = lambda x: float(max(x @ a for a in lower_alphas)) if x.sum() > 0 else 0.0  # noqa: E731

    def q(x, d):
        out = []
        for k, name in enumerate(root.actions):
            p = policy.pick(name, x, {})[0] if root.abstract[k] else policy.action_index(name)
            value = float(x @ model.R[:, p])
            pred = x @ T[p]
            for o in range(model.num_observations):
                joint = pred * model.O[p][:, o]
                mass = joint.sum()
                if mass <= 1e-15:
                    continue
                nxt = joint / mass
                v = leaf(nxt) if d <= 1 else max(leaf(nxt), max(q(nxt, d - 1)))
                value += model.discount * mass * v
            out.append(value)
        return out

    return np.array(q(np.asarray(b, dtype=float), depth))


#: (P(A wants), P(B wants)), independent; none near CareA's own switch from asking to serving (~0.6),
#: where the particles' X+ marginal could fall on the other side of it than the exact belief.
BELIEFS = [(0.5, 0.3), (0.97, 0.1), (0.1, 0.95), (0.85, 0.6), (0.02, 0.02)]


@pytest.mark.parametrize("depth", [1, 2])
def test_root_choice_equals_brute_force(planned, depth):
    domain, model, policy = planned
    # Many scenarios (sampling error ~0.05 of a value); at depth 1 one trial expands the root, and the
    # tree is the brute-force tree.
    settings = DespotSettings(scenarios=4000, depth=depth, trials=1 if depth == 1 else 50, xi=1e-6)
    policy.bind_model(model)
    root = policy.online_root
    from pearl_pomdp.hierarchy.online_root import OnlineRoot

    search = OnlineRoot(policy, model, settings, seed=3, bounds=root.bounds)
    alphas = root.bounds.lower_alphas_t.T
    names = [str(s) for s in model.states]
    grid = [("ANeed=want" in s, "BNeed=want" in s) for s in names]
    chosen = []
    for pa, pb in BELIEFS:
        b = np.array([(pa if a else 1 - pa) * (pb if w else 1 - pb) for a, w in grid])
        brute = _brute(policy, model, alphas, b, depth)
        decision = search.execute(b)
        lows = np.array([row["lower"] for row in decision.search["action_bounds"]])
        assert int(np.argmax(lows)) == int(np.argmax(brute)), (pa, pb, lows, brute)
        if depth == 1:
            np.testing.assert_allclose(lows, brute, atol=0.35)
        else:
            # DESPOT grows only the nodes its trials reach (down the best upper bound): a partial tree,
            # whose lower bounds lie below the full depth-2 tree's, with the same best action.
            assert np.all(lows <= brute + 0.35)
        # The executed primitive is what the chosen root action resolves to (CareA: its policy's pick).
        k = int(np.argmax(brute))
        expect = policy.pick("CareA", b, {})[0] if k == 0 else policy.action_index(["CareA", "ServeB", "Wait"][k])
        assert decision.action == expect
        chosen.append(decision.action_name)
    # The toy makes the root use each kind of action somewhere: serve A, ask A, serve B.
    assert {"ServeA", "ServeB"} <= set(chosen) and len(set(chosen)) >= 3, chosen


def test_decisions_are_deterministic_and_survive_save_and_load(planned, tmp_path):
    domain, model, policy = planned
    b = np.asarray(model.b0, dtype=float)
    first = policy.execute(b)
    again = policy.execute(b)
    assert first.action == again.action and first.search["lower"] == again.search["lower"]
    assert first.trace[0].subtask == "Care" and first.search["trials"] == 40
    assert first.search["nodes"] > 1 and first.search["gap"] == first.search["upper"] - first.search["lower"]
    loaded = load_hierarchical_policy(policy.save(tmp_path / "toy"), domain)
    other = loaded.execute(b)
    assert (other.action, other.search["lower"], other.search["nodes"]) == (
        first.action, first.search["lower"], first.search["nodes"])
    report = next(s for s in policy.report["subtasks"] if s["name"] == "Care")
    assert report["solver"] == "online" and report["b0_decision"]["trials"] == 40
    assert report["value_at_start"] == pytest.approx(first.search["lower"])


def test_veto_passes_over_the_forbidden_primitive(planned):
    domain, model, policy = planned
    names = [str(s) for s in model.states]
    b = np.array([1.0 if s.startswith("ANeed=want") and "BNeed=none" in s else 0.0 for s in names])
    assert policy.execute(b).action_name == "ServeA"
    vetoed = policy.execute_without(b, ["ServeA"])
    assert vetoed.action_name != "ServeA"
    with pytest.raises(PolicyError):
        policy.execute_without(b, list(model.actions))


def test_an_online_root_without_its_model_says_how_to_load_it(planned):
    domain, model, policy = planned
    bound = policy.online_root
    try:
        policy.online_root = None
        with pytest.raises(PolicyError, match="load_hierarchical_policy"):
            policy.execute(model.b0)
    finally:
        policy.online_root = bound


@pytest.mark.parametrize("text, where, words", [
    (HIERARCHY.replace("CareA: {actions: [AskA, ServeA]}", "CareA: {actions: [AskA, ServeA], solver: online}"),
     "subtasks.CareA.solver", "only the root"),
    (HIERARCHY.replace("solver: online, trials: 40", "solver: online, trials: null"), "subtasks.Care.trials",
     "needs trials"),
    (HIERARCHY.replace("solver: online, trials: 40", "solver: online, trials: 40, lookahead: 1"),
     "subtasks.Care.lookahead", "searches by itself"),
    (HIERARCHY.replace("solver: online, trials: 40", "solver: online, trials: 40, horizon: 5"),
     "subtasks.Care.horizon", "no horizon"),
    ("parameterize: corner\n" + HIERARCHY, "subtasks.Care.solver", "parameterize: policy"),
    (HIERARCHY.replace("solver: online", "solver: onlin"), "subtasks.Care.solver", "unknown solver"),
])
def test_bad_online_settings_name_the_field(text, where, words):
    domain = parse_domain(toy("no"))
    with pytest.raises(SpecError) as err:
        parse_hierarchy(text, domain.actions, _features(domain), source="toy.hierarchy.yaml")
    message = str(err.value)
    assert "toy.hierarchy.yaml" in message and where in message and words in message, message


def test_the_simulator_and_the_executive_run_it(planned):
    """The same class through `simulate` (batched protocol) and the core executive (what the policy node
    and `pearl experiment` run)."""
    from pearl_pomdp.executive import Executive
    from pearl_pomdp.simulate import simulate
    from pearl_pomdp.tracking import StepSettings

    domain, model, policy = planned
    result = simulate(model, policy, episodes=2, steps=6, seed=1)
    assert np.isfinite(result["mean"]) and result["episodes"] == 2
    decision = Executive(model, policy, domain=domain, settings=StepSettings(timeout_observation="quiet")).decide()
    assert decision.trace[0].subtask == "Care" and decision.search["trials"] == 40
    assert decision.action == policy.execute(model.b0).action


def test_the_policy_node_loads_it_from_a_plan_directory_or_plans_it(planned, tmp_path):
    """The policy node's loader (no node started): a saved directory comes back with its search bound to
    the model; an empty policy plans the hierarchy file at start-up, the root online."""
    pytest.importorskip("rclpy")
    from pearl_pomdp.nodes.hierarchical_policy import load_decider

    domain, model, policy = planned
    saved = policy.save(tmp_path / "toy")
    decider = load_decider(model, domain, str(saved), "")
    assert decider.execute(model.b0).action == policy.execute(model.b0).action
    hfile = tmp_path / "toy.hierarchy.yaml"
    hfile.write_text(HIERARCHY)
    fresh = load_decider(model, domain, "", str(hfile))
    assert fresh.online and fresh.execute(model.b0).action == policy.execute(model.b0).action
