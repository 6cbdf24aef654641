"""PomdpX writer/reader: well-formed XML in SARSOP's flat layout, exact round trips."""
from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest
import scipy.sparse as sp

from pearl_pomdp.errors import ModelFormatError
from pearl_pomdp.model import load_model
from pearl_pomdp.model.pomdp import Pomdp
from pearl_pomdp.model.pomdp_format import read_pomdp
from pearl_pomdp.model.pomdpx import format_pomdpx, parse_pomdpx, read_pomdpx, write_pomdpx

FAST = ["1d.POMDP", "4x3.95.POMDP", "cheese.95.POMDP", "hallway.POMDP", "hallway2.POMDP", "network.POMDP",
        "parr95.95.POMDP", "RockSample_4_4.pomdp", "shuttle.95.POMDP", "TagAvoid.pomdp", "tiger.95.POMDP",
        "tiger.aaai.POMDP"]


def _same(m: Pomdp, m2: Pomdp):
    assert m2.fingerprint() == m.fingerprint()
    assert (m2.states, m2.actions, m2.observations) == (m.states, m.actions, m.observations)
    assert m2.discount == m.discount
    assert np.array_equal(m2.O, m.O) and np.array_equal(m2.R, m.R) and np.array_equal(m2.b0, m.b0)
    for a in range(m.num_actions):
        assert (sp.csr_matrix(m.T[a]) != sp.csr_matrix(m2.T[a])).nnz == 0


@pytest.mark.parametrize("name", FAST)
def test_round_trip_identical(benchmarks_dir, name, tmp_path):
    m = read_pomdp(benchmarks_dir / name)
    path = write_pomdpx(m, tmp_path / "m.pomdpx")
    _same(m, read_pomdpx(path))
    _same(m, load_model(path))  # load_model dispatches on .pomdpx


@pytest.mark.slow
def test_round_trip_rocksample_7_8(benchmarks_dir, tmp_path):
    m = read_pomdp(benchmarks_dir / "RockSample_7_8.pomdp")
    _same(m, read_pomdpx(write_pomdpx(m, tmp_path / "rs78.pomdpx")))


def test_structure_is_sarsops_flat_layout(benchmarks_dir):
    m = read_pomdp(benchmarks_dir / "tiger.95.POMDP")
    root = ET.fromstring(format_pomdpx(m))  # well-formed
    assert root.tag == "pomdpx" and root.get("version") == "1.0"
    assert [c.tag for c in root] == ["Description", "Discount", "Variable", "InitialStateBelief",
                                     "StateTransitionFunction", "ObsFunction", "RewardFunction"]
    assert root.findtext("Discount") == "0.95"
    var = root.find("Variable")
    sv = var.find("StateVar")
    assert (sv.get("vnamePrev"), sv.get("vnameCurr"), sv.get("fullyObs")) == ("state_0", "state_1", "false")
    assert sv.findtext("ValueEnum").split() == ["tiger-left", "tiger-right"]
    assert var.find("ObsVar").findtext("ValueEnum").split() == ["tiger-left", "tiger-right"]
    assert var.find("ActionVar").findtext("ValueEnum").split() == ["listen", "open-left", "open-right"]
    assert var.find("RewardVar").get("vname") == "reward_agent"
    b = root.find("InitialStateBelief/CondProb")
    assert (b.findtext("Var"), b.findtext("Parent")) == ("state_0", "null")
    assert b.findtext("Parameter/Entry/Instance") == "-" and b.findtext("Parameter/Entry/ProbTable") == "0.5 0.5"
    t = root.find("StateTransitionFunction/CondProb")
    assert (t.findtext("Var"), t.findtext("Parent")) == ("state_1", "action_agent state_0")
    entries = [(e.findtext("Instance"), e.findtext("ProbTable")) for e in t.iter("Entry")]
    assert entries[0] == ("listen - -", "identity")
    assert ("open-left tiger-left -", "0.5 0.5") in entries
    o = root.find("ObsFunction/CondProb")
    assert (o.findtext("Var"), o.findtext("Parent")) == ("obs_sensor", "action_agent state_1")
    assert ("listen tiger-left -", "0.85 0.15") in [(e.findtext("Instance"), e.findtext("ProbTable")) for e in o.iter("Entry")]
    r = root.find("RewardFunction/Func")
    assert (r.findtext("Var"), r.findtext("Parent")) == ("reward_agent", "action_agent state_0")
    rewards = {e.findtext("Instance"): float(e.findtext("ValueTable")) for e in r.iter("Entry")}
    assert rewards == {"listen tiger-left": -1, "listen tiger-right": -1, "open-left tiger-left": -100,
                       "open-left tiger-right": 10, "open-right tiger-left": 10, "open-right tiger-right": -100}


def test_every_instance_matches_its_parents(benchmarks_dir):
    """SARSOP rejects an Instance whose token count is not parents + 1 (Func: parents)."""
    root = ET.fromstring(format_pomdpx(read_pomdp(benchmarks_dir / "TagAvoid.pomdp")))
    row_len = {"StateTransitionFunction/CondProb": 870, "ObsFunction/CondProb": 30, "RewardFunction/Func": 870}
    for section, n in (("StateTransitionFunction/CondProb", 3), ("ObsFunction/CondProb", 3), ("RewardFunction/Func", 2)):
        block = root.find(section)
        is_func = section.endswith("/Func")
        assert len(block.findtext("Parent").split()) + (0 if is_func else 1) == n
        for e in block.iter("Entry"):
            inst = e.findtext("Instance").split()
            assert len(inst) == n
            table = e.findtext("ValueTable" if is_func else "ProbTable")
            assert table == "identity" or len(table.split()) == (row_len[section] if inst[-1] == "-" else 1)


HAND = """<?xml version="1.0"?>
<pomdpx version="1.0" id="tiny">
<Discount>0.9</Discount>
<Variable>
<StateVar vnamePrev="x0" vnameCurr="x1"><NumValues>2</NumValues></StateVar>
<ObsVar vname="z"><ValueEnum>hear-l hear-r</ValueEnum></ObsVar>
<ActionVar vname="act"><ValueEnum>listen open</ValueEnum></ActionVar>
<RewardVar vname="r"/>
</Variable>
<InitialStateBelief><CondProb><Var>x0</Var><Parent>null</Parent><Parameter>
<Entry><Instance>-</Instance><ProbTable>uniform</ProbTable></Entry></Parameter></CondProb></InitialStateBelief>
<StateTransitionFunction><CondProb><Var>x1</Var><Parent>act x0</Parent><Parameter type="TBL">
<Entry><Instance>listen - -</Instance><ProbTable>identity</ProbTable></Entry>
<Entry><Instance>open * *</Instance><ProbTable>0.5</ProbTable></Entry>
</Parameter></CondProb></StateTransitionFunction>
<ObsFunction><CondProb><Var>z</Var><Parent>act x1</Parent><Parameter type="TBL">
<Entry><Instance>* - -</Instance><ProbTable>0.5 0.5 0.5 0.5</ProbTable></Entry>
<Entry><Instance>listen s0 -</Instance><ProbTable>0.85 0.15</ProbTable></Entry>
<Entry><Instance>listen s1 hear-r</Instance><ProbTable>0.85</ProbTable></Entry>
<Entry><Instance>listen s1 hear-l</Instance><ProbTable>0.15</ProbTable></Entry>
</Parameter></CondProb></ObsFunction>
<RewardFunction><Func><Var>r</Var><Parent>act x0</Parent><Parameter type="TBL">
<Entry><Instance>listen *</Instance><ValueTable>-1</ValueTable></Entry>
<Entry><Instance>open -</Instance><ValueTable>-100 10</ValueTable></Entry>
</Parameter></Func></RewardFunction>
</pomdpx>
"""


def test_reads_handwritten_flat_file_with_wildcards():
    m = parse_pomdpx(HAND, source="tiny.pomdpx")
    assert m.states == ["s0", "s1"] and m.actions == ["listen", "open"]  # NumValues -> s0, s1 (SARSOP's rule)
    assert m.discount == 0.9 and m.b0.tolist() == [0.5, 0.5]
    assert np.array_equal(m.T_dense()[0], np.eye(2)) and np.array_equal(m.T_dense()[1], np.full((2, 2), 0.5))
    assert m.O[0].tolist() == [[0.85, 0.15], [0.15, 0.85]] and m.O[1].tolist() == [[0.5, 0.5], [0.5, 0.5]]
    assert m.R.tolist() == [[-1, -100], [-1, 10]]


@pytest.mark.parametrize("bad,words", [
    (HAND.replace("</pomdpx>", ""), ["not well-formed XML"]),
    (HAND.replace("listen s0 -", "listen s7 -"), ["unknown value 's7'"]),
    (HAND.replace("<ProbTable>0.85</ProbTable>", "<ProbTable>0.5</ProbTable>"), ["ObsFunction", "sums to 0.65"]),
    (HAND.replace("listen - -", "listen -"), ["Instance has 2 tokens, expected 3"]),
    (HAND.replace("-100 10", "-100"), ["table has 1 numbers, expected 2"]),
    (HAND.replace('<StateVar vnamePrev="x0"', '<StateVar vnamePrev="y0" vnameCurr="y1"><NumValues>2</NumValues>'
                  '</StateVar><StateVar vnamePrev="x0"'), ["only the flat form"]),
])
def test_bad_pomdpx_raises_model_format_error(bad, words):
    with pytest.raises(ModelFormatError) as info:
        parse_pomdpx(bad, source="tiny.pomdpx")
    msg = str(info.value)
    assert msg.startswith("tiny.pomdpx")
    for w in words:
        assert w in msg, msg


def test_unsafe_names_are_rewritten_to_tokens():
    m = Pomdp.create(["a b", "-"], ["go"], ["null", "z"], [np.eye(2)], np.full((1, 2, 2), 0.5), np.zeros((2, 1)),
                     discount=0.5)
    root = ET.fromstring(format_pomdpx(m))
    assert root.find("Variable/StateVar").findtext("ValueEnum").split() == ["a_b", "s-"]
    assert root.find("Variable/ObsVar").findtext("ValueEnum").split() == ["onull", "z"]
    m2 = parse_pomdpx(format_pomdpx(m))
    assert m2.states == ["a_b", "s-"] and np.array_equal(m2.O, m.O)


def test_pearl_convert_both_ways(benchmarks_dir, tmp_path, capsys):
    import json

    from pearl_pomdp.cli import main

    src = benchmarks_dir / "hallway.POMDP"
    m = read_pomdp(src)
    x = tmp_path / "h.pomdpx"
    assert main(["convert", str(src), str(x), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["fingerprint"] == m.fingerprint() and out["states"] == 60 and out["format"] == "pomdpx"
    back = tmp_path / "h.pomdp"
    assert main(["convert", str(x), str(back)]) == 0
    _same(m, read_pomdp(back))
    assert main(["convert", str(back), str(tmp_path / "h.txt")]) == 2
    assert "unknown output format" in capsys.readouterr().err
