"""Factored YAML domains: validation messages, and compilation checked against hand-computed entries."""
import itertools
import textwrap

import numpy as np
import pytest
import scipy.sparse as sp

from pearl_pomdp.errors import SpecError
from pearl_pomdp.model.domain_yaml import load_domain, parse_domain

# A two-feature domain small enough to compute every entry by hand.
TINY = textwrap.dedent("""\
    name: tiny
    discount: 0.9
    features:
      Door: [closed, open]
      Light: [off, on]
    start:
      Door: closed
      Light: {off: 0.75, on: 0.25}
    modalities:
      Eye: [dark, bright]
      Ear: [yes, no]
    actions:
      Push:
        effects:
          Door:
            parents: [Door, Light]
            table:
              "closed,on": {open: 0.8, keep: 0.2}   # pushing works only in the light
              "*": keep
      Flip:
        effects:
          Light: {parents: [Light], table: {off: on, on: {off: 0.9, on: 0.1}}}
    observations:
      default:
        parents: [Light]
        table:
          off: {dark: 0.9, bright: 0.1}
          on: {dark: 0.2, bright: 0.7, yes: 0.1}
      Flip:
        mix:
          - {weight: 0.5, parents: [Door], table: {closed: dark, open: bright}}
          - {weight: 0.5, table: {"*": {yes: 0.5, no: 0.5}}}
    rewards:
      - {action: Push, reward: -1, why: effort}
      - {action: Push, when: {Door: closed, Light: on}, reward: 10, why: goal}
      - {action: "*", when: {Door: open}, reward: 2, why: fresh air}
    """)


def tiny():
    return parse_domain(TINY, source="tiny.yaml")


def test_tiny_sizes_names_and_start():
    d = tiny()
    m = d.compile()
    assert m.states == ["Door=closed,Light=off", "Door=closed,Light=on", "Door=open,Light=off", "Door=open,Light=on"]
    assert m.actions == ["Push", "Flip"]
    assert m.observations == ["dark", "bright", "yes", "no"]  # 'yes'/'no' stay strings (YAML 1.2 booleans)
    assert d.modalities == {"Eye": ["dark", "bright"], "Ear": ["yes", "no"]}
    assert np.allclose(m.b0, [0.75, 0.25, 0, 0])
    assert m.discount == 0.9


def test_tiny_transitions_by_hand():
    T = tiny().compile().T_dense()
    push = np.array([[1, 0, 0, 0],            # closed,off: dark → nothing happens
                     [0, 0.2, 0, 0.8],        # closed,on: opens with 0.8
                     [0, 0, 1, 0],
                     [0, 0, 0, 1]])
    # Flip: off→on surely; on→off 0.9 (the switch sticks 10%); Door persists.
    flip = np.array([[0, 1, 0, 0],
                     [0.9, 0.1, 0, 0],
                     [0, 0, 0, 1],
                     [0, 0, 0.9, 0.1]])
    assert np.allclose(T[0], push)
    assert np.allclose(T[1], flip)


def test_tiny_observations_and_mixture_by_hand():
    O = tiny().compile().O
    assert np.allclose(O[0], [[0.9, 0.1, 0, 0], [0.2, 0.7, 0.1, 0], [0.9, 0.1, 0, 0], [0.2, 0.7, 0.1, 0]])
    # Flip: half the time the eye reports the door (closed→dark, open→bright), half the ear says yes/no evenly.
    assert np.allclose(O[1], [[0.5, 0, 0.25, 0.25], [0.5, 0, 0.25, 0.25], [0, 0.5, 0.25, 0.25], [0, 0.5, 0.25, 0.25]])


def test_tiny_rewards_sum_all_matching_rules():
    R = tiny().compile().R
    assert np.allclose(R, [[-1, 0], [9, 0], [1, 2], [1, 2]])


def test_structure_queries():
    d = tiny()
    assert d.transition_parents("Push") == {"Door": ["Door", "Light"], "Light": ["Light"]}
    assert d.transition_parents("Flip") == {"Door": ["Door"], "Light": ["Light"]}
    assert d.reward_features("Push") == {"Door", "Light"}
    assert d.reward_features("Flip") == {"Door"}
    assert d.observation_parents("Push") == {"Light"}
    assert d.observation_parents("Flip") == {"Door"}
    assert d.modality_of("yes") == "Ear" and d.modality_of("bright") == "Eye"
    with pytest.raises(KeyError, match="unknown observation symbol 'loud'"):
        d.modality_of("loud")


def test_state_index_values_and_marginals():
    d = tiny()
    assert d.state_index({"Door": "open", "Light": "off"}) == 2
    assert d.state_values.tolist() == [[0, 0], [0, 1], [1, 0], [1, 1]]
    assert d.state_assignment(3) == {"Door": "open", "Light": "on"}
    marg = d.feature_marginals(np.array([0.1, 0.2, 0.3, 0.4]))
    assert np.allclose(marg["Door"], [0.3, 0.7]) and np.allclose(marg["Light"], [0.4, 0.6])
    with pytest.raises(KeyError, match="missing: Light"):
        d.state_index({"Door": "open"})
    with pytest.raises(KeyError, match="Door has no value 'ajar'"):
        d.state_index({"Door": "ajar", "Light": "on"})


def test_feature_marginals_equal_sums_over_the_states_with_each_value():
    """Per feature and value, the marginal is the belief summed over the states whose assignment
    has that value (computed here state by state from state_assignment, not from the product order)."""
    d = load_domain(__import__("pathlib").Path(__file__).resolve().parents[1] / "config" / "pearl.domain.yaml")
    assert len(set(d.radix.tolist())) > 1   # uneven radices: a wrong reshape would mix features
    b = np.random.default_rng(3).random(d.num_states)
    b /= b.sum()
    expected = {f.name: np.zeros(len(f)) for f in d.features}
    for s in range(d.num_states):
        for name, value in d.state_assignment(s).items():
            expected[name][d.feature(name).index(value)] += b[s]
    marg = d.feature_marginals(b)
    assert list(marg) == [f.name for f in d.features]
    for name, values in expected.items():
        assert np.allclose(marg[name], values, atol=1e-14, rtol=0), name


def test_state_names_spell_each_states_assignment_in_index_order():
    d = load_domain(__import__("pathlib").Path(__file__).resolve().parents[1] / "config" / "pearl.domain.yaml")
    names = d.state_names()
    assert len(names) == d.num_states
    for s, name in enumerate(names):
        assert name == ",".join(f"{k}={v}" for k, v in d.state_assignment(s).items()), s


def test_sparse_transition_build_equals_brute_force_product():
    """transition_matrix expands supports feature by feature; compare with Π_f P(s'_f | s) on every (s, s')."""
    d = load_domain(__import__("pathlib").Path(__file__).resolve().parents[1] / "config" / "pearl.domain.yaml")
    sv = d.state_values
    rng = np.random.default_rng(0)
    for a in ("GuideToPhysio", "RingDoorBell", "RemindPhysioAppt"):
        T = d.transition_matrix(a).toarray()
        factors = [d.feature_transition(a, f) for f in range(len(d.features))]
        for s in rng.choice(d.num_states, 40, replace=False):
            brute = np.prod([factors[f][s][sv[:, f]] for f in range(len(d.features))], axis=0)
            assert np.allclose(T[s], brute)


def test_a_compilation_reads_each_distinct_feature_table_once_and_builds_the_same_T():
    """compile() shares each feature's factors among the actions with an equal table (Pearl: far fewer
    tables than actions x features); its T is the one transition_matrix builds alone, bit for bit."""
    d = load_domain(__import__("pathlib").Path(__file__).resolve().parents[1] / "config" / "pearl.domain.yaml")
    factors: dict = {}
    shared = [d.transition_matrix(a, factors) for a in range(len(d.actions))]
    assert len(factors) < len(d.actions) * len(d.features) / 3
    for a, Ta in enumerate(d.compile().T):
        alone = d.transition_matrix(a)
        assert Ta.shape == alone.shape == shared[a].shape
        dense = np.asarray(Ta.toarray() if hasattr(Ta, "toarray") else Ta)
        assert dense.tobytes() == alone.toarray().tobytes() == shared[a].toarray().tobytes()


def _expanded_feature_by_feature(d, a):
    """T[a] as the numpy build before the C kernel made it (kept here as the reference): each entry
    expanded into its state's non-zero factors of the next feature, in value order."""
    S = d.num_states
    rows, cols, probs = np.arange(S, dtype=np.int64), np.zeros(S, dtype=np.int64), np.ones(S)
    for f, stride in enumerate(d.strides):
        ptr, v_all, p_all = d._state_factors(a, f, None)
        count = ptr[rows + 1] - ptr[rows]
        e_idx = np.repeat(np.arange(rows.shape[0]), count)
        k = np.repeat(ptr[rows] - (np.cumsum(count) - count), count) + np.arange(e_idx.shape[0])
        probs, rows, cols = probs[e_idx] * p_all[k], rows[e_idx], cols[e_idx] + v_all[k] * stride
    return sp.csr_matrix((probs, (rows, cols)), shape=(S, S))


@pytest.mark.parametrize("name", ["pearl", "pearl_day", "reception"])
def test_the_c_build_of_t_is_the_feature_by_feature_expansion_bit_for_bit(name):
    """transition_matrix's rows come from _step_kernel.product_rows: the same entries in the same order,
    the same products to the last bit and the same index types as the numpy expansion it replaced."""
    d = load_domain(__import__("pathlib").Path(__file__).resolve().parents[1] / "config" / f"{name}.domain.yaml")
    for a in range(len(d.actions)):
        built, reference = d.transition_matrix(a), _expanded_feature_by_feature(d, a)
        assert built.nnz > d.num_states       # rows of several entries: products of several factors
        for part in ("indptr", "indices", "data"):
            got, want = getattr(built, part), getattr(reference, part)
            assert got.dtype == want.dtype and got.tobytes() == want.tobytes(), (d.actions[a], part)


def test_product_rows_refuses_inconsistent_input():
    from pearl_pomdp.online._step_kernel import product_rows

    # two states, one feature of two values: state 0 stays (p 1), state 1 moves to 0 or stays (0.25, 0.75)
    ptrs, values, probs = np.array([[0, 1, 3]]), np.array([0, 0, 1]), np.array([1.0, 0.25, 0.75])
    strides, indptr = np.array([1]), np.array([0, 1, 3])
    indices, data = np.empty(3, dtype=np.int32), np.empty(3)
    product_rows(ptrs, values, probs, strides, indptr, indices, data)
    assert indices.tolist() == [0, 0, 1] and data.tolist() == [1.0, 0.25, 0.75]
    with pytest.raises(ValueError, match=r"indptr does not hold the rows' sizes .* first wrong at state 1"):
        product_rows(ptrs, values, probs, strides, np.array([0, 1, 2]), indices[:2], data[:2])
    with pytest.raises(ValueError, match=r"feature 0's factors of state 1, ptrs\[0, 1:1 \+ 2\] = \[1, 4\]"):
        product_rows(np.array([[0, 1, 4]]), values, probs, strides, indptr, indices, data)
    with pytest.raises(ValueError, match=r"state 1 has an entry in column 2, not a state \(0 \.\. 1\)"):
        product_rows(ptrs, np.array([0, 0, 2]), probs, strides, indptr, indices, data)
    with pytest.raises(ValueError, match=r"shapes disagree"):
        product_rows(ptrs, values, probs[:2], strides, indptr, indices, data)
    with pytest.raises(ValueError, match=r"indices_out must hold int32 or int64"):
        product_rows(ptrs, values, probs, strides, indptr, data, data)


def edit(old, new):
    assert old in TINY, old
    return TINY.replace(old, new)


BAD = [
    # (spec text, expected fragments of the message)
    (edit('"closed,on": {open: 0.8, keep: 0.2}', '"closed,on": {open: 0.8, keep: 0.17}'),
     ["tiny.yaml:18:", "actions.Push.effects.Door[closed,on]", "row sums to 0.97, expected 1"]),
    (edit("parents: [Door, Light]", "parents: [Door, Lamp]"),
     ["actions.Push.effects.Door.parents[1]", "unknown feature 'Lamp'", "features: Door, Light"]),
    (edit('"closed,on": {open: 0.8', '"closed,dim": {open: 0.8'),
     ["actions.Push.effects.Door[closed,dim]", "unknown value 'dim' of parent Light"]),
    (edit('"closed,on": {open: 0.8, keep: 0.2}', '"closed,on": {ajar: 0.8, keep: 0.2}'),
     ["actions.Push.effects.Door[closed,on].ajar", "unknown value of Door 'ajar'"]),
    (edit('          "*": keep\n', ""),
     ["actions.Push.effects.Door", "no row for Door,Light=closed,off", "tables have no implicit default"]),
    (edit('{off: on, on: {off: 0.9, on: 0.1}}', '{off: on, on: {off: 0.9, on: 0.1}, "*": off}'),
     ["actions.Flip.effects.Light[*]", "row is never used"]),
    (edit("on: {dark: 0.2, bright: 0.7, yes: 0.1}", "on: {dark: 0.2, bright: 0.7, maybe: 0.1}"),
     ["observations.default[on].maybe", "unknown observation symbol 'maybe'"]),
    (edit("on: {dark: 0.2, bright: 0.7, yes: 0.1}", "on: {dark: 0.2, bright: 0.7, yes: lots}"),
     ["observations.default[on].yes", "probability 'lots' is not a number"]),
    (edit("{weight: 0.5, table", "{weight: 0.4, table"), ["observations.Flip.mix", "weights sum to 0.9, expected 1"]),
    (edit("  Flip:\n    mix:", "  Jump:\n    mix:"), ["observations.Jump", "unknown action 'Jump'"]),
    (edit("{action: Push, reward: -1, why: effort}", "{action: Pull, reward: -1, why: effort}"),
     ["rewards[0].action", "unknown action 'Pull'"]),
    (edit("{action: Push, reward: -1, why: effort}", "{action: Push, reward: -1}"),
     ["tiny.yaml:34:", "rewards[0]", "missing 'why'"]),
    (edit("when: {Door: closed, Light: on}", "when: {Door: shut, Light: on}"),
     ["rewards[1].when.Door", "unknown value 'shut' of Door"]),
    (edit("reward: 10, why: goal", "reward: ten, why: goal"), ["rewards[1].reward", "'ten' is not a finite number"]),
    (edit("discount: 0.9", "discount: 1.5"), ["discount", "not a number in (0, 1]"]),
    (edit("  Light: [off, on]\n", "  Light: [off, on, off]\n"), ["features.Light", "value 'off' listed twice"]),
    (edit("  Ear: [yes, no]", "  Ear: [yes, dark]"), ["modalities.Ear[1]", "already belongs to modality Eye"]),
    (edit("  Light: {off: 0.75, on: 0.25}", "  Light: {off: 0.75, on: 0.5}"), ["start.Light", "row sums to 1.25"]),
    (edit("Door: [closed, open]", "Door: closed"), ["features.Door", "expected a list, got the string 'closed'"]),
    (edit("name: tiny", "name: tiny\nfeature: {}"), ["feature", "unknown top-level key"]),
    (edit("  Flip:\n    effects:", "  Flip:\n    effect:"), ["actions.Flip.effect", "unknown key"]),
    (edit("Light: {parents: [Light]", "Light: {parents: [Light, Light]"), ["parents[1]", "listed twice"]),
    (edit('          "*": keep\n', '          "*": keep\n          "open": keep\n'),
     ["[open]", "row key has 1 value(s), expected 2"]),
    ("discount: [", ["tiny.yaml:", "YAML syntax"]),
    (edit("  Push:\n    effects:", "  Push:\n    effects: {}\n  Push:\n    effects:"),
     ["Push", "duplicate key"]),
]


@pytest.mark.parametrize("text,fragments", BAD, ids=[f[-1][:40] for _, f in BAD])
def test_validation_errors_name_file_field_and_problem(text, fragments):
    with pytest.raises(SpecError) as info:
        parse_domain(text, source="tiny.yaml")
    msg = str(info.value)
    for fragment in fragments:
        assert fragment in msg, msg


def test_load_domain_names_the_file(tmp_path):
    path = tmp_path / "bad.domain.yaml"
    path.write_text(edit("reward: 10, why: goal", "reward: 10"))
    with pytest.raises(SpecError, match=r"bad\.domain\.yaml:35: rewards\[1\]: missing 'why'"):
        load_domain(path)


def test_load_model_dispatches_yaml(tmp_path):
    from pearl_pomdp.model import load_model

    path = tmp_path / "tiny.domain.yaml"
    path.write_text(TINY)
    m = load_model(path)
    assert m.fingerprint() == tiny().compile().fingerprint()
    assert m.metadata["features"] == {"Door": ["closed", "open"], "Light": ["off", "on"]}


def test_every_parent_combination_compiles_to_a_distribution():
    d = tiny()
    m = d.compile()
    for a in range(2):
        assert np.allclose(m.T_dense()[a].sum(1), 1) and np.allclose(m.O[a].sum(1), 1)
    # wildcard alternatives: "closed|open,on" covers both doors with light on
    text = edit('"closed,on": {open: 0.8, keep: 0.2}', '"closed|open,on": {open: 1.0}')
    T = parse_domain(text).compile().T_dense()
    assert T[0][1, 3] == 1 and T[0][3, 3] == 1 and T[0][0, 0] == 1
    assert list(itertools.chain(*d.transition_table("Push", "Door")[0])) == list("DoorLight")


@pytest.mark.parametrize("fmt", ["pomdp", "pomdpx"])
def test_export_command_round_trips_the_compiled_arrays(tmp_path, fmt, capsys):
    """`pearl export` writes what other solvers read; reading it back gives the same arrays."""
    import json
    from pathlib import Path

    from pearl_pomdp.cli import main
    from pearl_pomdp.model.pomdp_format import read_pomdp
    from pearl_pomdp.model.pomdpx import read_pomdpx

    domain = Path(__file__).resolve().parents[1] / "config" / "table4.domain.yaml"
    out = tmp_path / f"t4.{fmt}"
    assert main(["export", str(domain), "--format", fmt, "--out", str(out), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert (info["states"], info["actions"], info["observations"], info["format"]) == (8, 14, 12, fmt)
    want = load_domain(domain).compile()
    got = (read_pomdp if fmt == "pomdp" else read_pomdpx)(out)
    assert np.allclose(got.T_dense(), want.T_dense()) and np.allclose(got.O, want.O)
    assert np.allclose(got.R, want.R) and np.allclose(got.b0, want.b0) and got.discount == want.discount
    assert main(["export", str(domain), "--format", fmt]) == 0          # no --out: the model on stdout
    assert out.read_text() == capsys.readouterr().out


def test_export_command_rejects_mismatched_extension(tmp_path, capsys):
    from pathlib import Path

    from pearl_pomdp.cli import main

    domain = Path(__file__).resolve().parents[1] / "config" / "table4.domain.yaml"
    assert main(["export", str(domain), "--format", "pomdp", "--out", str(tmp_path / "x.pomdpx")]) == 2
    assert "the extension says pomdpx but --format is pomdp" in capsys.readouterr().err


def test_explicit_start():
    text = edit("start:\n  Door: closed\n  Light: {off: 0.75, on: 0.25}\n",
                "start:\n  states:\n    - {state: {Door: open, Light: on}, p: 0.6}\n"
                "    - {state: {Door: closed, Light: off}, p: 0.4}\n")
    assert np.allclose(parse_domain(text).compile().b0, [0.4, 0, 0, 0.6])
    bad = text.replace("p: 0.4}", "p: 0.3}")
    with pytest.raises(SpecError, match=r"start\.states: probabilities sum to 0\.9, expected 1"):
        parse_domain(bad)
    bad = text.replace("{Door: closed, Light: off}", "{Door: closed}")
    with pytest.raises(SpecError, match=r"start\.states\[1\]\.state: missing feature Light"):
        parse_domain(bad)
