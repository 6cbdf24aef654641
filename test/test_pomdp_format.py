"""The .pomdp reader/writer against the benchmark files and hand-made inputs.

Expected sizes and discounts are the table of ``test/data/pomdp/README.md``; spot values
are read off the files by eye; the s'-dependent rewards are checked against a naive reference
reduction written here (pomdp-solve's rule: last matching R line per (a, s, s', o), then
``Σ_s' T Σ_o O R``).
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from pearl_pomdp.errors import ModelFormatError
from pearl_pomdp.model import load_model
from pearl_pomdp.model.pomdp import Pomdp
from pearl_pomdp.model.pomdp_format import parse_pomdp, read_pomdp
from pearl_pomdp.model.pomdp_writer import format_pomdp, write_pomdp

# file: (S, A, Z, discount)  — test/data/pomdp/README.md
EXPECTED = {
    "1d.POMDP": (4, 2, 2, 0.75),
    "4x3.95.POMDP": (11, 4, 6, 0.95),
    "4x5x2.95.POMDP": (39, 4, 4, 0.95),
    "cheese.95.POMDP": (11, 4, 7, 0.95),
    "hallway.POMDP": (60, 5, 21, 0.95),
    "hallway2.POMDP": (92, 5, 17, 0.95),
    "mini-hall2.POMDP": (13, 3, 9, 0.95),
    "network.POMDP": (7, 4, 2, 0.95),
    "paint.95.POMDP": (4, 4, 2, 0.95),
    "parr95.95.POMDP": (7, 3, 6, 0.95),
    "RockSample_4_4.pomdp": (257, 9, 2, 0.95),
    "RockSample_7_8.pomdp": (12545, 13, 2, 0.95),
    "saci-s12-a6-z5.95.POMDP": (12, 6, 5, 0.95),
    "shuttle.95.POMDP": (8, 3, 5, 0.95),
    "stand-tiger.95.POMDP": (4, 4, 4, 0.95),
    "TagAvoid.pomdp": (870, 5, 30, 0.95),
    "tiger.95.POMDP": (2, 3, 2, 0.95),
    "tiger.aaai.POMDP": (2, 3, 2, 0.75),
    "web-ad.POMDP": (4, 3, 5, 0.95),
}

_CACHE: dict = {}


def _load(benchmarks_dir: Path, name: str) -> Pomdp:
    if name not in _CACHE:
        _CACHE[name] = read_pomdp(benchmarks_dir / name)
    return _CACHE[name]


def _dense(m) -> np.ndarray:
    return m.toarray() if sp.issparse(m) else np.asarray(m)


def test_every_benchmark_file_is_listed(benchmarks_dir):
    files = sorted(p.name for p in benchmarks_dir.iterdir() if p.suffix.lower() == ".pomdp")
    assert files == sorted(EXPECTED)


def test_data_files_match_their_readme(benchmarks_dir):
    """Every model file is the one its provenance row names: same bytes (SHA-256), same sizes."""
    import hashlib

    from conftest import MODELS

    rows = {}
    for line in (MODELS / "README.md").read_text(encoding="utf-8").splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 7 and re.fullmatch(r"`[0-9a-f]{64}`.*", cells[4]):
            name = cells[0].split("`")[1]
            rows[name] = (cells[1], int(cells[3]), cells[4][1:65])
    assert sorted(rows) == sorted(EXPECTED)
    stored = sorted(p.name for p in MODELS.iterdir() if p.name != "README.md")
    assert stored == sorted(n + ".xz" if n == "RockSample_7_8.pomdp" else n for n in EXPECTED)
    for name, (sizes, size, digest) in rows.items():
        data = (benchmarks_dir / name).read_bytes()
        assert (len(data), hashlib.sha256(data).hexdigest()) == (size, digest), name
        S, A, Z, _ = EXPECTED[name]
        assert sizes == f"{S}/{A}/{Z}", name


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_benchmark_loads_with_published_sizes(benchmarks_dir, name):
    m = _load(benchmarks_dir, name)
    S, A, Z, g = EXPECTED[name]
    assert (m.num_states, m.num_actions, m.num_observations) == (S, A, Z)
    assert m.discount == g
    assert len(m.T) == A and all(t.shape == (S, S) for t in m.T)
    assert m.O.shape == (A, S, Z) and m.R.shape == (S, A) and m.b0.shape == (S,)
    # exact distributions after loading (renormalised within the tolerance)
    for Ta in m.T:
        assert np.allclose(np.asarray(Ta.sum(axis=1)).ravel(), 1.0, atol=1e-12)
    assert np.allclose(m.O.sum(axis=2), 1.0, atol=1e-12)
    assert abs(m.b0.sum() - 1.0) < 1e-12
    assert m.is_sparse == (S > 2000)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_round_trip_is_identical(benchmarks_dir, name, tmp_path):
    m = _load(benchmarks_dir, name)
    out = write_pomdp(m, tmp_path / f"copy_{name}")
    m2 = read_pomdp(out)
    assert m2.fingerprint() == m.fingerprint()
    assert (m2.states, m2.actions, m2.observations) == (m.states, m.actions, m.observations)
    assert m2.discount == m.discount
    assert np.array_equal(m2.O, m.O) and np.array_equal(m2.R, m.R) and np.array_equal(m2.b0, m.b0)
    for a in range(m.num_actions):
        d = sp.csr_matrix(m.T[a]) - sp.csr_matrix(m2.T[a])
        assert d.nnz == 0 or np.abs(d.data).max() == 0.0
    assert m2.metadata["renormalised"] == {"T_rows": 0, "O_rows": 0, "start": False}
    # and writing again gives the same text
    assert format_pomdp(m2).split("\n", 1)[1] == out.read_text().split("\n", 1)[1]


def test_tiger_spot_values(benchmarks_dir):
    m = _load(benchmarks_dir, "tiger.95.POMDP")
    assert m.states == ["tiger-left", "tiger-right"]
    assert m.actions == ["listen", "open-left", "open-right"]
    assert m.observations == ["tiger-left", "tiger-right"]
    listen, left, right = 0, 1, 2
    assert np.array_equal(_dense(m.T[listen]), np.eye(2))  # identity
    assert np.array_equal(_dense(m.T[left]), np.full((2, 2), 0.5))  # uniform
    assert m.O[listen, 0, 0] == 0.85 and m.O[listen, 0, 1] == 0.15 and m.O[listen, 1, 1] == 0.85
    assert np.array_equal(m.O[right], np.full((2, 2), 0.5))
    assert m.R.tolist() == [[-1.0, -100.0, 10.0], [-1.0, 10.0, -100.0]]
    assert m.b0.tolist() == [0.5, 0.5]
    assert m.metadata["values"] == "reward" and m.name == "tiger.95"


def test_parr95_start_include_and_wildcards(benchmarks_dir):
    m = _load(benchmarks_dir, "parr95.95.POMDP")
    assert m.b0.tolist() == [1.0, 0, 0, 0, 0, 0, 0]  # start include: I
    assert m.metadata["start"] == "include"
    i, hi, lo = (m.index("states", n) for n in ("I", "hi-A", "lo-A"))
    for a in range(3):  # T : * : I : hi-A 0.5
        assert _dense(m.T[a])[i, hi] == 0.5 and _dense(m.T[a])[i, lo] == 0.5
    # R: * : plus1 : * : * 2.0
    assert m.R[m.index("states", "plus1")].tolist() == [2.0, 2.0, 2.0]
    assert m.R[m.index("states", "minus1")].tolist() == [0.0, 0.0, 0.0]


def test_network_commented_start_is_uniform(benchmarks_dir):
    m = _load(benchmarks_dir, "network.POMDP")
    assert np.array_equal(m.b0, np.full(7, 1 / 7))
    assert m.metadata["start"] == "default"
    # T: unrestrict : s000 : s000 then the probability on the next line
    assert _dense(m.T[0])[0, 0] == 0.5 and _dense(m.T[0])[0, 1] == 0.3


def _naive_reward(path: Path, m: Pomdp) -> np.ndarray:
    """Reference reduction for files whose R lines are all ``R: a : s : s' : o v``."""
    S, A, Z = m.num_states, m.num_actions, m.num_observations
    full = np.zeros((A, S, S, Z))

    def sel(tok, kind):
        if tok == "*":
            return slice(None)
        names = getattr(m, kind)
        return names.index(tok) if tok in names else int(tok)

    for line in path.read_text().splitlines():
        line = line.split("#")[0]
        if not line.startswith("R"):
            continue
        f = [x.strip() for x in line[line.index(":") + 1:].split(":")]
        a, s, s2, rest = f
        o, v = rest.split()
        full[sel(a, "actions"), sel(s, "states"), sel(s2, "states"), sel(o, "observations")] = float(v)
    T = m.T_dense()
    return np.einsum("asp,apo,aspo->sa", T, m.O, full)


@pytest.mark.parametrize("name", ["hallway.POMDP", "hallway2.POMDP", "1d.POMDP", "cheese.95.POMDP", "shuttle.95.POMDP",
                                  "tiger.95.POMDP", "4x3.95.POMDP"])
def test_next_state_rewards_reduced_like_pomdp_solve(benchmarks_dir, name):
    m = _load(benchmarks_dir, name)
    assert np.allclose(m.R, _naive_reward(benchmarks_dir / name, m), rtol=0, atol=1e-12)


def test_hand_computed_reduced_rewards(benchmarks_dir):
    hall = _load(benchmarks_dir, "hallway.POMDP")
    # T: 1 : 34 : 58 0.8 is the only goal (56-59) successor of state 34 under action 1
    assert hall.R[34, 1] == pytest.approx(0.8, abs=1e-15)
    assert hall.metadata["reward_depends_on_next"] is True
    shuttle = _load(benchmarks_dir, "shuttle.95.POMDP")
    # R: Backup : 3 : 0 : * 10, and T: Backup row 3 = 0.7 0 0 0.3 ...
    assert shuttle.R[3, shuttle.index("actions", "Backup")] == pytest.approx(7.0, abs=1e-14)
    one_d = _load(benchmarks_dir, "1d.POMDP")
    # R: * : * : goal : goal 1.0; middle --e0--> goal with probability 1, O(goal|goal) = 1
    assert one_d.R[1, 1] == 1.0 and one_d.R[2, 0] == 1.0 and one_d.R[3, 0] == 0.0


def test_tagavoid_last_line_wins_and_start_renormalised(benchmarks_dir):
    m = _load(benchmarks_dir, "TagAvoid.pomdp")
    north = m.index("actions", "North")
    s0 = m.index("states", "s0")
    T = _dense(m.T[north])
    # T: * : s0 : s0 1.0, later T: North : s0 : s0 0.0 and three entries
    assert T[s0, s0] == 0.0
    assert T[s0, m.index("states", "s300")] == 0.6
    assert np.count_nonzero(T[s0]) == 3
    assert m.metadata["renormalised"]["start"] is True  # file's start sums to 0.99999946
    assert m.b0[0] == pytest.approx(0.00118906 / 0.99999946, rel=1e-9)
    assert m.R[m.index("states", "s59"), m.index("actions", "Catch")] == 0.0


def test_rocksample_identity_and_sparse(benchmarks_dir):
    m = _load(benchmarks_dir, "RockSample_4_4.pomdp")
    c1 = m.index("actions", "Check_1")
    assert np.array_equal(_dense(m.T[c1]), np.eye(257))
    assert m.O[c1, 0].tolist() == [0.4788353901883975, 0.5211646098116025]
    assert m.O[m.index("actions", "N"), 5].tolist() == [1.0, 0.0]  # O: * : * : good 1.0
    assert m.b0.sum() == 1.0 and np.count_nonzero(m.b0) == 16


# ------------------------------------------------------------------ grammar corners
HEAD = """discount: 0.9
values: reward
states: a b c
actions: x y
observations: o p
"""


def _model(body: str, head: str = HEAD) -> Pomdp:
    return parse_pomdp(head + body, source="corner.pomdp")


def test_every_granularity_and_override():
    m = _model("""start exclude: b
T: * uniform
T: x : a 0 1 0          # row
T: y
1 0 0
0 0 1
0 1 0
T: x : c : c 1.0
T: x : c : a 0.0        # zero the earlier uniform entries of row c
T: x : c : b 0
O: * : * : o 1
O: y : b 0.25 0.75
O: y
uniform
O: x : c : p 1
O: x : c : o 0
R: * : * : * : * 1
R: x : a : b : * 5      # s'-dependent: T[x][a] = (0, 1, 0) -> 5
R: y : c
1 2
3 4
5 6                     # rows are s'; T[y] takes c to b; O[y] uniform -> (3+4)/2
R: y : b : c -1 -3      # row over o: mean -2
""")
    assert m.b0.tolist() == [0.5, 0.0, 0.5]
    assert m.metadata["start"] == "exclude"
    Tx, Ty = _dense(m.T[0]), _dense(m.T[1])
    assert Tx.tolist() == [[0, 1, 0], [1 / 3, 1 / 3, 1 / 3], [0, 0, 1]]
    assert Ty.tolist() == [[1, 0, 0], [0, 0, 1], [0, 1, 0]]
    assert m.O[0].tolist() == [[1, 0], [1, 0], [0, 1]]
    assert m.O[1].tolist() == [[0.5, 0.5]] * 3
    assert m.R[0, 0] == 5.0 and m.R[1, 0] == 1.0 and m.R[2, 0] == 1.0
    assert m.R[2, 1] == 3.5 and m.R[1, 1] == -2.0 and m.R[0, 1] == 1.0


def test_counts_numeric_indices_cost_and_reset():
    m = _model("""start: 0.2 0.8 0
T: 0 : 0 reset
T: 0 : 1 : 1 1
T: * : 2 uniform
T: 1 identity
O: * uniform
R: 1 : * : * : * 4
""", head="discount: 0.5\nvalues: cost\nstates: 3\nactions: 2\nobservations: 2\n")
    assert m.states == ["0", "1", "2"] and m.actions == ["0", "1"]
    assert m.b0.tolist() == [0.2, 0.8, 0.0]
    T0 = _dense(m.T[0])
    assert T0[0].tolist() == [0.2, 0.8, 0.0]  # reset = start belief
    assert T0[2].tolist() == [1 / 3] * 3
    assert m.R[:, 1].tolist() == [-4.0, -4.0, -4.0] and m.metadata["values"] == "cost"
    m2 = parse_pomdp(format_pomdp(m))
    assert "values: cost" in format_pomdp(m) and np.array_equal(m2.R, m.R) and m2.fingerprint() == m.fingerprint()


def test_start_forms():
    body = "T: * identity\nO: * uniform\n"
    assert _model("start: uniform\n" + body).b0.tolist() == [1 / 3] * 3
    assert _model("start: b\n" + body).b0.tolist() == [0, 1, 0]
    assert _model("start include: a 2\n" + body).b0.tolist() == [0.5, 0, 0.5]
    assert _model(body).metadata["start"] == "default"
    m = _model("start: 0.333333 0.333333 0.333334\n" + body)
    assert m.b0.sum() == 1.0


def test_signs_exponents_and_line_breaks():
    m = _model("T: * identity\nO: *\n1 0\n1e-1 9E-1\n0.5\n0.5\nR: x : * : * : * - 2.5e1\nR: y : a : * : * +3\n")
    assert m.O[0, 1].tolist() == [0.1, 0.9]
    assert m.R[:, 0].tolist() == [-25.0] * 3 and m.R[0, 1] == 3.0


def test_load_model_dispatches(benchmarks_dir):
    assert load_model(benchmarks_dir / "tiger.95.POMDP").num_states == 2


def test_writer_renames_invalid_names_and_is_atomic(tmp_path):
    m = Pomdp.create(["f=1,g=a", "f=2,g=a"], ["go on", "reset"], ["1", "x"], [np.eye(2)] * 2,
                     np.full((2, 2, 2), 0.5), np.array([[1.0, 2.0], [3.0, 4.0]]), discount=0.9)
    path = tmp_path / "named.pomdp"
    write_pomdp(m, path)
    m2 = read_pomdp(path)
    assert m2.states == ["f_1_g_a", "f_2_g_a"] and m2.actions == ["go_on", "reset_"] and m2.observations == ["o1", "x"]
    assert np.array_equal(m2.R, m.R)
    assert [p.name for p in tmp_path.iterdir()] == ["named.pomdp"]  # no temp file left


# ------------------------------------------------------------------ errors
TIGER = """discount: 0.95
values: reward
states: tiger-left tiger-right
actions: listen open-left open-right
observations: tiger-left tiger-right
start: 0.5 0.5
T: listen identity
T: open-left uniform
T: open-right uniform
O: listen
0.85 0.15
0.15 0.85
O: * : * uniform
O: listen : * 0.85 0.15
R: listen : * : * : * -1
"""
N = TIGER.count("\n")
OK_O = TIGER.replace("O: listen : * 0.85 0.15\n", "")

BAD = [
    # (text, line, words in the message)
    (TIGER + "T: listen : tiger-middle : tiger-left 1.0\n", N + 1, ["unknown state 'tiger-middle'"]),
    (TIGER + "O: listen : tiger-left 0.5 0.3 0.2\n", N + 1, ["has 3 numbers, expected 2"]),
    (TIGER + "T: listen\n1 0\n0\n", N + 3, ["has 3 numbers, expected 4"]),
    (TIGER + "\nT: listen : tiger-left : tiger-right 0.4\n", N + 2, ["T: listen : tiger-left", "sums to 1.4"]),
    (TIGER.replace("discount: 0.95\n", ""), 5, ["missing 'discount:'"]),
    (TIGER + "T: listen : tiger-left : tiger-left 0.5x\n", N + 1, ["0.5x"]),
    (TIGER + "T: listen : tiger-left : tiger-left 1.5\n", N + 1, ["probability", "not in [0, 1]"]),
    (TIGER + "T: listen : tiger-left : tiger-left -0.5\n", N + 1, ["probability", "not in [0, 1]"]),
    (TIGER + "T: 5 : 0 : 0 1.0\n", N + 1, ["action index 5 is out of range"]),
    (TIGER.replace("states: tiger-left tiger-right", "states: tl tl"), 3, ["listed twice"]),
    (TIGER.replace("start: 0.5 0.5", "start: 0.5 0.3"), 6, ["sum to 0.8"]),
    (TIGER + "foo: 1\n", N + 1, ["unexpected 'foo'"]),
    (TIGER.replace("observations: tiger-left tiger-right\n", ""), 5, ["missing 'observations:'", "MDP"]),
    (TIGER.replace("states: tiger-left tiger-right", "states: start end"), 3, []),
    (TIGER + "O: listen identity\n", N + 1, ["'identity' is not valid for O"]),
    (TIGER + "R: listen 1 2\n", N + 1, ["MDP form"]),
    (TIGER.replace("discount: 0.95", "discount 0.95"), 1, ["expected ':'"]),
    (TIGER + "R: listen : * : * : * 1 # caf\u00e9\nR: listen : * : * : * \u00e91\n", N + 2, ["illegal character"]),
    (TIGER + "R: listen : tiger-left : * : nothing 3\n", N + 1, ["unknown observation 'nothing'"]),
    (TIGER.replace("discount: 0.95", "discount: 1.5"), 1, ["discount 1.5 is not in (0, 1]"]),
    (TIGER + "T: listen : tiger-left\n", N + 1, ["row of T", "has 0 numbers, expected 2"]),
    (TIGER + "start: uniform\n", N + 1, ["start belief given twice"]),
    (TIGER + "O: open-left : tiger-left : tiger-left 0.0\n", N + 1, ["O: open-left : tiger-left", "sums to 0.5"]),
    (TIGER.replace("states: tiger-left tiger-right", "states: tiger-left tiger/right"), 3, ["bad state name 'tiger/right'"]),
]


@pytest.mark.parametrize("text,line,words", BAD, ids=[f"bad{i}" for i in range(len(BAD))])
def test_errors_name_file_line_and_problem(text, line, words):
    with pytest.raises(ModelFormatError) as info:
        parse_pomdp(text, source="bad.pomdp")
    err = info.value
    msg = str(err)
    assert err.source == "bad.pomdp"
    assert err.line == line, msg
    assert msg.startswith(f"bad.pomdp:{line}: "), msg
    for w in words:
        assert w in msg, msg


def test_error_from_file_names_the_path(tmp_path):
    p = tmp_path / "broken.pomdp"
    p.write_text(TIGER + "T: listen : nowhere : tiger-left 1\n")
    with pytest.raises(ModelFormatError, match=re.escape(f"{p}:{N + 1}: ")):
        read_pomdp(p)


def test_valid_variants_of_the_error_table_load():
    # later statements win: O: * : * uniform replaces the listen matrix, then one row comes back
    assert parse_pomdp(TIGER).O[0].tolist() == [[0.85, 0.15], [0.85, 0.15]]
    assert parse_pomdp(OK_O).O[0].tolist() == [[0.5, 0.5], [0.5, 0.5]]


def test_reward_matrix_zeros_do_not_override_but_row_zeros_do():
    """pomdp-solve keeps an R matrix sparse (zeros absent); a row over o is a full vector."""
    m = _model("""T: * identity
O: * uniform
R: * : * : * : * 7
R: x : a
0 0
0 0
0 0
R: y : a : a 0 0
""")
    assert m.R[0, 0] == 7.0  # the all-zero matrix left the earlier 7 in place
    assert m.R[0, 1] == 0.0  # the row for s' = a (the only successor) set both observations to 0
    assert m.R[1, 0] == 7.0 and m.R[1, 1] == 7.0


def test_hallway_reduced_rewards_match_sarsops_conversion(benchmarks_dir):
    """APPL's own examples/POMDPX/Hallway.pomdpx (converted from this file by SARSOP's tools) lists
    exactly four rewards R(a1, s32) = 0.05, R(a1, s33) = 0.05, R(a1, s34) = 0.8, R(a1, s35) = 0.05."""
    m = _load(benchmarks_dir, "hallway.POMDP")
    nz = {(m.actions[a], m.states[s]): round(float(m.R[s, a]), 12) for s, a in zip(*np.nonzero(m.R))}
    assert nz == {("1", "32"): 0.05, ("1", "33"): 0.05, ("1", "34"): 0.8, ("1", "35"): 0.05}
