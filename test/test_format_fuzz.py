"""Fuzzing the model readers: any input loads or raises ModelFormatError, never anything else;
any valid model survives write -> read exactly (.pomdp and PomdpX)."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pearl_pomdp.errors import ModelFormatError
from pearl_pomdp.model.pomdp import Pomdp
from pearl_pomdp.model.pomdp_format import RESERVED_WORDS, parse_pomdp
from pearl_pomdp.model.pomdp_writer import format_pomdp
from pearl_pomdp.model.pomdpx import format_pomdpx, parse_pomdpx

FUZZ = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])

TIGER = """discount: 0.95
values: reward
states: tiger-left tiger-right
actions: listen open-left open-right
observations: tiger-left tiger-right
start: 0.5 0.5
T:listen
identity
T:open-left
uniform
T: open-right : * uniform
O:listen
0.85 0.15
0.15 0.85
O: open-left : tiger-left : * 0.5
O: open-left : tiger-right 0.5 0.5
O: open-right uniform
R:listen : * : * : * -1
R:open-left : tiger-left : * : * -100
R:open-left : tiger-right : * : * 10
R:open-right : tiger-left : tiger-right 10 20
R:open-right : tiger-right
-100 -100
1e2 +3
"""
PARR = """discount: 0.95
values: cost
states: 3
actions: a b
observations: 2
start include: 0 2
T : * : 0 : 1 0.5
T : * : 0 : 2 0.5
T : a : 1 reset
T : b : 1 : 1 1.0
T : * : 2 : 0 1.0
O : * : * : 0 1.0
R: * : 2 : * : * 2.0
R: a : * : 1 : 1 4.0
"""
VOCAB = ["discount", "values", "states", "actions", "observations", "start", "include", "exclude", "T", "O", "R",
         "uniform", "identity", "reset", "reward", "cost", ":", "*", "-", "+", "#", "\n", "0", "1", "2", "3", "0.5",
         "0.25", "1.0", "-1", "1e-3", "1e999", "1.5", ".5", "1.2.3", "0x10", "1_0", "nan", "inf", "tiger-left",
         "tiger-right", "listen", "open-left", "a", "b", "x", "é", "\t", "\r\n", "::", "*:", "T:", "O:*", "99999999"]


def _check(text: str):
    try:
        m = parse_pomdp(text, source="fuzz.pomdp")
    except ModelFormatError as err:
        assert str(err).startswith("fuzz.pomdp")
        return None
    assert isinstance(m, Pomdp)
    m.check(1e-9)  # what loads is a valid model with exact distributions
    return m


@FUZZ
@given(st.lists(st.sampled_from(VOCAB), max_size=60))
def test_token_soup(tokens):
    _check(" ".join(tokens))


@FUZZ
@given(st.sampled_from([TIGER, PARR]), st.lists(st.sampled_from(VOCAB), max_size=30))
def test_valid_preamble_then_soup(base, tokens):
    head = base[: base.index("start")]
    _check(head + " ".join(tokens))


@FUZZ
@given(st.sampled_from([TIGER, PARR]), st.data())
def test_mutations_of_valid_files(base, data):
    toks = base.replace("\n", " \n ").split(" ")
    for _ in range(data.draw(st.integers(1, 4))):
        op = data.draw(st.sampled_from(["delete", "replace", "insert", "duplicate", "truncate"]))
        i = data.draw(st.integers(0, max(len(toks) - 1, 0)))
        if not toks:
            break
        if op == "delete":
            del toks[i]
        elif op == "replace":
            toks[i] = data.draw(st.sampled_from(VOCAB))
        elif op == "insert":
            toks.insert(i, data.draw(st.sampled_from(VOCAB)))
        elif op == "duplicate":
            toks.insert(i, toks[i])
        else:
            toks = toks[:i]
    _check(" ".join(toks))


def test_unmutated_fuzz_bases_load():
    tiger = _check(TIGER)
    # open-right from tiger-left: s' uniform; s' = tiger-right pays 10 / 20 by o (uniform) -> 0.5 * 15
    # open-right from tiger-right: s' = tiger-left pays -100, s' = tiger-right 100 / 3 -> 0.5 * -100 + 0.5 * 51.5
    assert tiger.R.tolist() == [[-1.0, -100.0, 7.5], [-1.0, 10.0, -24.25]]
    assert tiger.O[1].tolist() == [[0.5, 0.5], [0.5, 0.5]]
    parr = _check(PARR)
    assert parr.b0.tolist() == [0.5, 0.0, 0.5]
    # cost: R negated; a from 0 reaches 1 w.p. 0.5 and O(0|1) = 1 (reward 4 only for o = 1) -> 0
    assert parr.R.tolist() == [[0.0, 0.0], [0.0, 0.0], [-2.0, -2.0]]


# ------------------------------------------------------------------ valid models round-trip
NAME = st.from_regex(r"[A-Za-z][A-Za-z0-9_\-]{0,6}", fullmatch=True).filter(lambda n: n not in RESERVED_WORDS)


def _names(draw, n, allow_count=True):
    if allow_count and draw(st.booleans()):
        return [str(i) for i in range(n)]
    return draw(st.lists(NAME, min_size=n, max_size=n, unique=True))


def _dist(draw, n, rng):
    k = draw(st.integers(1, n))
    idx = rng.choice(n, size=k, replace=False)
    row = np.zeros(n)
    row[idx] = rng.random(k) + 1e-3
    if draw(st.booleans()):
        row[idx] = np.round(row[idx], 3) + 0.001
    return row / row.sum()


@st.composite
def models(draw):
    S, A, Z = draw(st.integers(1, 7)), draw(st.integers(1, 4)), draw(st.integers(1, 5))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    T = [np.array([_dist(draw, S, rng) for _ in range(S)]) for _ in range(A)]
    if draw(st.booleans()):
        T[0] = np.eye(S)
    O = np.array([[_dist(draw, Z, rng) for _ in range(S)] for _ in range(A)])
    R = rng.normal(scale=draw(st.sampled_from([1e-9, 1.0, 1e6])), size=(S, A))
    R[rng.random((S, A)) < 0.4] = draw(st.sampled_from([0.0, -1.0, 10.0]))
    b0 = _dist(draw, S, rng)
    gamma = draw(st.sampled_from([0.95, 1.0, 0.123456789, 1 / 3]))
    m = Pomdp.create(_names(draw, S), _names(draw, A), _names(draw, Z), T, O, R, b0=b0, discount=gamma,
                     sparse=draw(st.booleans()))
    if draw(st.booleans()):
        m.metadata["values"] = "cost"
    return m


def _identical(m: Pomdp, m2: Pomdp):
    assert (m2.states, m2.actions, m2.observations) == (m.states, m.actions, m.observations)
    assert m2.discount == m.discount
    assert np.array_equal(m2.O, m.O) and np.array_equal(m2.R, m.R) and np.array_equal(m2.b0, m.b0)
    for a in range(m.num_actions):
        assert (sp.csr_matrix(m.T[a]) != sp.csr_matrix(m2.T[a])).nnz == 0
    assert m2.fingerprint() == m.fingerprint()


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(models())
def test_random_models_round_trip_pomdp(m):
    _identical(m, parse_pomdp(format_pomdp(m)))


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(models())
def test_random_models_round_trip_pomdpx(m):
    _identical(m, parse_pomdpx(format_pomdpx(m)))


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_pomdpx_mutations(data):
    text = format_pomdpx(parse_pomdp(TIGER))
    for _ in range(data.draw(st.integers(1, 3))):
        i = data.draw(st.integers(0, len(text) - 1))
        j = data.draw(st.integers(i, min(len(text), i + 20)))
        text = text[:i] + data.draw(st.sampled_from(["", "<", ">", "x", " ", "-", "*", "1", "0.5", "</Entry>"])) + text[j:]
    try:
        m = parse_pomdpx(text, source="fuzz.pomdpx")
    except ModelFormatError as err:
        assert str(err).startswith("fuzz.pomdpx")
    else:
        m.check(1e-9)
