"""Fuzzing every file the project reads (issue 7): each input loads or raises the project's own
error naming the file (and field, line or offset) — never another exception, a hang, or a large
allocation from a small file.

Budget: every hypothesis test is derandomized (same examples on every run, so CI is
deterministic) with a small ``max_examples``; the whole file runs in well under 40 s on a
loaded 2-core machine. ``bench/fuzz.py`` runs the same checks with many more examples.
"""
from __future__ import annotations

import shutil
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pearl_pomdp.errors import ModelFormatError, PearlError, PolicyError, SpecError
from pearl_pomdp.model.pomdp_format import parse_pomdp

REPO = Path(__file__).resolve().parents[1]
#: The benchmark models in the repository (test/data/pomdp/README.md); the fuzzed ones are plain text.
BENCH = REPO / "test" / "data" / "pomdp"
FUZZ = settings(max_examples=60, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                       HealthCheck.data_too_large])

# ------------------------------------------------------------------ mutations (shared with bench/fuzz.py)
MUTATIONS = ("truncate", "delete_line", "duplicate_line", "swap_tokens", "replace_token", "flip_byte", "insert_text")
INSERTS = ["1000000000", "-1", "nan", "inf", "1e999", "*", ":", "&a", "*a", "!!python/object:os.system", "[", "{",
           "'", "\"", "\t", "- ", "? ", "~", "null", "0x10", "1_000", "é", "\x00", "%YAML 1.1", "---", "<<: *a"]


def mutate(text: str, kind: str, i: int, j: int, pick: int) -> str:
    """One deterministic mutation of ``text``: ``i``/``j`` are positions (taken modulo the size)."""
    if kind == "truncate":
        return text[: i % (len(text) + 1)]
    lines = text.split("\n")
    if kind == "delete_line":
        del lines[i % len(lines)]
        return "\n".join(lines)
    if kind == "duplicate_line":
        k = i % len(lines)
        lines.insert(j % (len(lines) + 1), lines[k])
        return "\n".join(lines)
    tokens = text.split(" ")
    if kind == "swap_tokens":
        a, b = i % len(tokens), j % len(tokens)
        tokens[a], tokens[b] = tokens[b], tokens[a]
        return " ".join(tokens)
    if kind == "replace_token":
        tokens[i % len(tokens)] = INSERTS[pick % len(INSERTS)]
        return " ".join(tokens)
    if kind == "flip_byte":
        data = bytearray(text.encode("utf-8"))
        if data:
            data[i % len(data)] ^= 1 << (pick % 8)
        return data.decode("utf-8", errors="replace")
    k = i % (len(text) + 1)
    return text[:k] + INSERTS[pick % len(INSERTS)] + text[k:]


mutations = st.tuples(st.sampled_from(MUTATIONS), st.integers(0, 10**6), st.integers(0, 10**6), st.integers(0, 100))


def expect_own_error(fn, error=PearlError, names=None):
    """Run ``fn``; a raised exception must be ``error`` whose text starts with/contains ``names``."""
    try:
        return fn()
    except error as err:
        if names is not None:
            assert names in str(err), str(err)
        return err


# ------------------------------------------------------------------ .pomdp reader
POMDP_FILES = ["tiger.95.POMDP", "parr95.95.POMDP", "shuttle.95.POMDP", "4x3.95.POMDP", "network.POMDP"]


@pytest.fixture(scope="module")
def pomdp_texts():
    return {name: (BENCH / name).read_text() for name in POMDP_FILES}


@FUZZ
@given(st.sampled_from(POMDP_FILES), mutations)
def test_pomdp_reader_mutated_benchmarks(pomdp_texts, name, mutation):
    text = mutate(pomdp_texts[name], *mutation)
    result = expect_own_error(lambda: parse_pomdp(text, source=f"fuzz/{name}"), ModelFormatError, f"fuzz/{name}")
    if not isinstance(result, Exception):
        result.check(1e-6)  # what loads is a valid model


@pytest.mark.parametrize("declared", ["states: 1000000000", "observations: 1000000000", "actions: 1000000000",
                                      "states: 99999999999999999999999"])
def test_pomdp_huge_declared_counts_fail_before_allocating(declared):
    """A 100-byte file declaring a billion states must fail at once, naming the limit."""
    kw = declared.split(":")[0]
    head = {"states": "states: 2", "actions": "actions: 2", "observations": "observations: 2"}
    head[kw] = declared
    text = "discount: 0.9\nvalues: reward\n" + "\n".join(head.values()) + "\nT: * identity\nO: * uniform\n"
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        with pytest.raises(ModelFormatError) as info:
            parse_pomdp(text, source="huge.pomdp")
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert time.perf_counter() - t0 < 5.0
    assert peak < 20e6, f"{peak / 1e6:.0f} MB allocated before failing"
    msg = str(info.value)
    assert msg.startswith("huge.pomdp:") and kw in msg and "10,000,000" in msg, msg


def test_pomdp_product_limit_before_allocating():
    """Each count within limits but O = A×S×Z far too big: refused before numpy allocates it."""
    text = "discount: 0.9\nvalues: reward\nstates: 5000000\nactions: 1000\nobservations: 1000\n"
    tracemalloc.start()
    try:
        with pytest.raises(ModelFormatError) as info:
            parse_pomdp(text, source="big.pomdp")
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 50e6 and "limit" in str(info.value), (peak, str(info.value))


# ------------------------------------------------------------------ domain / hierarchy / scenario YAML
CONFIG = REPO / "config"
DOMAIN_FILES = ["pearl.domain.yaml", "table4.domain.yaml"]
SCENARIO_FILES = sorted(p.name for p in (CONFIG / "scenarios").glob("*.yaml"))


@pytest.fixture(scope="module")
def pearl_domain():
    from pearl_pomdp.model.domain_yaml import load_domain

    return load_domain(CONFIG / "pearl.domain.yaml")


def _parse_domain(text, source):
    from pearl_pomdp.model.domain_yaml import parse_domain

    return parse_domain(text, source=source)


def _parse_hierarchy(text, source, domain):
    from pearl_pomdp.hierarchy.spec import parse_hierarchy

    features = {f.name: list(f.values) for f in domain.features}
    return parse_hierarchy(text, domain.actions, features, source=source)


def _parse_scenarios(text, source):
    from pearl_sim.nursing_home.scenario import parse_scenarios

    return parse_scenarios(text, source=source)


@FUZZ
@given(st.sampled_from(DOMAIN_FILES), mutations)
def test_domain_yaml_mutations(name, mutation):
    text = mutate((CONFIG / name).read_text(), *mutation)
    expect_own_error(lambda: _parse_domain(text, f"fuzz/{name}"), SpecError, f"fuzz/{name}")


@FUZZ
@given(mutations)
def test_hierarchy_yaml_mutations(pearl_domain, mutation):
    text = mutate((CONFIG / "pearl.hierarchy.yaml").read_text(), *mutation)
    expect_own_error(lambda: _parse_hierarchy(text, "fuzz/h.yaml", pearl_domain), SpecError, "fuzz/h.yaml")


@FUZZ
@given(st.sampled_from(SCENARIO_FILES), mutations)
def test_scenario_yaml_mutations(name, mutation):
    text = mutate((CONFIG / "scenarios" / name).read_text(), *mutation)
    expect_own_error(lambda: _parse_scenarios(text, f"fuzz/{name}"), SpecError, f"fuzz/{name}")


def _bomb(levels: int = 9) -> str:
    """'Billion laughs': 9 nested aliases of 9 → 9**9 (387 million) leaves once expanded."""
    lines = ['_l0: &l0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for i in range(1, levels):
        lines.append(f"_l{i}: &l{i} [" + ", ".join([f"*l{i - 1}"] * 9) + "]")
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("kind,key", [("domain", "features"), ("domain", "name"), ("domain", "actions"),
                                      ("hierarchy", "root"), ("hierarchy", "subtasks"),
                                      ("scenario", "name"), ("scenario", "questions"), ("scenario", "episodes")])
def test_yaml_alias_bombs_are_bounded(pearl_domain, kind, key):
    """A few hundred bytes of nested aliases never expand into gigabytes or minutes."""
    text = _bomb() + f"{key}: *l8\n"
    parse = {"domain": lambda: _parse_domain(text, "bomb.yaml"),
             "hierarchy": lambda: _parse_hierarchy(text, "bomb.yaml", pearl_domain),
             "scenario": lambda: _parse_scenarios(text, "bomb.yaml")}[kind]
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        with pytest.raises(SpecError) as info:
            parse()
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert time.perf_counter() - t0 < 5.0
    assert peak < 100e6, f"{peak / 1e6:.0f} MB"
    assert str(info.value).startswith("bomb.yaml"), str(info.value)


@pytest.mark.parametrize("tag", ["!!python/object/apply:os.system ['touch /tmp/pwned']",
                                 "!!python/name:os.system", "!!binary aGVsbG8="])
def test_yaml_python_tags_never_construct(pearl_domain, tag, tmp_path):
    for parse in (lambda t: _parse_domain(t, "tag.yaml"), lambda t: _parse_scenarios(t, "tag.yaml"),
                  lambda t: _parse_hierarchy(t, "tag.yaml", pearl_domain)):
        result = expect_own_error(lambda: parse(f"name: {tag}\n"), SpecError, "tag.yaml")
        assert isinstance(result, SpecError)


# ------------------------------------------------------------------ policy files
@pytest.fixture(scope="module")
def saved_policy(tmp_path_factory):
    from pearl_pomdp.policy_io import save_policy
    from pearl_pomdp.solution import AlphaVectorPolicy

    from pearl_pomdp.model.pomdp_format import read_pomdp

    model = read_pomdp(BENCH / "tiger.95.POMDP")
    policy = AlphaVectorPolicy(np.array([[1.0, -2.0], [0.5, 0.5], [-2.0, 1.0]]), np.array([1, 0, 2]))
    d = tmp_path_factory.mktemp("policy")
    save_policy(d / "tiger.npz", policy, model, {"solver": "test"})
    return model, d


@FUZZ
@given(st.sampled_from(["tiger.npz", "tiger.json"]), st.sampled_from(["truncate", "flip", "garbage", "empty"]),
       st.integers(0, 10**6), st.integers(0, 7))
def test_policy_files_corrupted(saved_policy, tmp_path_factory, which, how, pos, bit):
    from pearl_pomdp.policy_io import load_policy

    model, src = saved_policy
    d = tmp_path_factory.mktemp("p")
    for f in src.iterdir():
        shutil.copy(f, d / f.name)
    target = d / which
    data = bytearray(target.read_bytes())
    if how == "truncate":
        data = data[: pos % len(data)]
    elif how == "flip":
        data[pos % len(data)] ^= 1 << bit
    elif how == "garbage":
        data = bytearray(np.random.default_rng(pos).integers(0, 256, 64 + pos % 2000, dtype=np.uint8).tobytes())
    else:
        data = bytearray()
    target.write_bytes(bytes(data))
    result = expect_own_error(lambda: load_policy(d / "tiger.npz", model), PolicyError, str(d))
    if which == "tiger.npz":
        # The header holds the arrays' sha256: any change to the .npz is refused.
        assert isinstance(result, PolicyError)
    elif not isinstance(result, Exception):
        # A harmless header change (whitespace) still gives exactly the saved policy.
        np.testing.assert_array_equal(result.alphas, [[1.0, -2.0], [0.5, 0.5], [-2.0, 1.0]])


def test_hierarchical_policy_files_corrupted(tmp_path):
    """A hierarchical policy directory with a truncated/garbage file raises PolicyError."""
    from pearl_pomdp.hierarchy import load_hierarchical_policy, load_hierarchy, plan
    from pearl_pomdp.model.domain_yaml import load_domain

    domain = load_domain(CONFIG / "table4.domain.yaml")
    from pearl_pomdp.hierarchy.spec import flat_hierarchy

    good = tmp_path / "good"
    plan(domain, flat_hierarchy(domain.actions, solver="pointbased", time_limit=2.0)).save(good)
    files = sorted(p.name for p in good.iterdir())
    assert files
    rng = np.random.default_rng(7)
    for name in files:
        for how in ("truncate", "garbage", "empty", "missing"):
            d = tmp_path / f"{name}-{how}"
            shutil.copytree(good, d)
            data = (d / name).read_bytes()
            if how == "truncate":
                (d / name).write_bytes(data[: len(data) // 2])
            elif how == "garbage":
                (d / name).write_bytes(rng.integers(0, 256, 500, dtype=np.uint8).tobytes())
            elif how == "empty":
                (d / name).write_bytes(b"")
            else:
                (d / name).unlink()
            with pytest.raises(PolicyError) as info:
                load_hierarchical_policy(d, domain)
            assert str(d) in str(info.value), str(info.value)
    _ = load_hierarchy  # the planned file format is the one load_hierarchy's plans save


# ------------------------------------------------------------------ bags
def _std_string(text: str) -> bytes:
    raw = text.encode() + b"\x00"
    pad = b"\x00" * (-len(raw) % 4)
    return b"\x00\x01\x00\x00" + len(raw).to_bytes(4, "little") + raw + pad


def _write_bag(path: Path, n: int = 30, **kw) -> list:
    from pearl_pomdp.bags.metadata import QosProfile
    from pearl_pomdp.bags.writer import BagWriter

    sent = []
    with BagWriter(path, **kw) as bag:
        bag.add_topic("/pearl/speech", "std_msgs/msg/String", qos=[QosProfile()])
        bag.add_topic("/pearl/action", "std_msgs/msg/String", qos=[QosProfile()])
        for i in range(n):
            topic = "/pearl/speech" if i % 3 else "/pearl/action"
            data = _std_string(f"message {i}")
            bag.write(topic, data, 1_000_000_000 + i * 1000)
            sent.append((topic, data))
    return sent


@pytest.fixture(scope="module")
def bags(tmp_path_factory):
    d = tmp_path_factory.mktemp("bags")
    plain = _write_bag(d / "plain")
    chunked = _write_bag(d / "chunked", chunk_size=300, compression="zstd")
    return {"plain": (d / "plain", plain), "chunked": (d / "chunked", chunked)}


def _mcap(bag_dir: Path) -> Path:
    return next(bag_dir.glob("*.mcap"))


@FUZZ
@given(st.sampled_from(["plain", "chunked"]), st.sampled_from(["truncate", "flip", "flip4", "garbage_tail"]),
       st.integers(0, 10**7), st.integers(0, 255))
def test_bag_corruption(bags, tmp_path_factory, which, how, pos, value):
    """A damaged MCAP file: BagError naming the file (and offset), or a read of messages that were written."""
    from pearl_pomdp.bags.reader import BagReader

    src, sent = bags[which]
    data = bytearray(_mcap(src).read_bytes())
    k = pos % len(data)
    if how == "truncate":
        data = data[:k]
    elif how == "flip":
        data[k] ^= value or 1
    elif how == "flip4":
        data[k:k + 4] = bytes([value, 255, 255, 255])[: len(data[k:k + 4])]
    else:
        data = data[:k] + np.random.default_rng(pos).integers(0, 256, 200, dtype=np.uint8).tobytes()
    f = tmp_path_factory.mktemp("bag") / "x_0.mcap"
    f.write_bytes(bytes(data))
    t0 = time.perf_counter()
    try:
        reader = BagReader(f, salvage=True)
    except PearlError as err:  # BagError, or PearlError for a damaged QoS/metadata text
        assert str(err).startswith(str(f)), str(err)
        if "offset" not in str(err):
            assert "not" in str(err) or "cut" in str(err), str(err)
        return
    finally:
        assert time.perf_counter() - t0 < 5.0
    got = [(m.topic, m.data) for m in reader.messages]
    if how == "truncate":
        # Cut short: a prefix of what was written, nothing invented.
        assert got == sent[: len(got)]
        if which == "plain":
            assert reader.salvaged or len(got) == len(sent)
    else:
        assert len(got) <= len(sent) + 1  # a flipped payload byte may change data, never invent records


def test_bag_truncation_every_offset_keeps_every_complete_message(bags, tmp_path):
    """Unchunked bag cut at each record boundary region: exactly the messages before the cut."""
    from pearl_pomdp.bags.reader import BagError, BagReader

    src, sent = bags["plain"]
    data = _mcap(src).read_bytes()
    counts = []
    for k in range(0, len(data), max(1, len(data) // 150)):
        f = tmp_path / f"cut{k}.mcap"
        f.write_bytes(data[:k])
        try:
            got = [(m.topic, m.data) for m in BagReader(f).messages]
        except BagError as err:
            assert "offset" in str(err) and str(f) in str(err)
            continue
        assert got == sent[: len(got)]
        counts.append(len(got))
    assert counts == sorted(counts) and counts[-1] >= len(sent) - 1


def test_bag_wrong_schema_and_wrong_type_on_topic(tmp_path):
    """A non-ros2 profile, a non-CDR channel, a topic recorded with two types: BagError naming it."""
    from mcap.writer import Writer

    from pearl_pomdp.bags.reader import BagError, BagReader

    def build(name, profile="ros2", encoding="cdr", second_type=None):
        f = tmp_path / f"{name}.mcap"
        with open(f, "wb") as out:
            w = Writer(out)
            w.start(profile=profile, library="fuzz")
            s = w.register_schema("std_msgs/msg/String", "ros2msg", b"string data")
            c = w.register_channel("/pearl/speech", encoding, s, {})
            w.add_message(c, log_time=1, data=_std_string("hi"), publish_time=1)
            if second_type:
                s2 = w.register_schema(second_type, "ros2msg", b"float64[] data")
                c2 = w.register_channel("/pearl/speech", encoding, s2, {})
                w.add_message(c2, log_time=2, data=b"\x00\x01\x00\x00" + bytes(8), publish_time=2)
            w.finish()
        return f

    cases = {build("profile", profile="ros1"): "profile",
             build("json", encoding="json"): "encoding",
             build("twotypes", second_type="std_msgs/msg/Float64MultiArray"): "/pearl/speech"}
    for f, word in cases.items():
        with pytest.raises(BagError) as info:
            BagReader(f)
        assert str(info.value).startswith(str(f)) and word in str(info.value), str(info.value)


@pytest.mark.parametrize("payload", [b"", b"\x00", b"\x00\x01\x00\x00", b"\x00\x01\x00\x00\xff\xff\xff\xff",
                                     b"\x00\x01\x00\x00\x05\x00\x00\x00ab", b"\x00\x01\x00\x00\x02\x00\x00\x00\xff\x00"])
def test_garbage_cdr_on_action_topic_is_a_bag_error(tmp_path, payload):
    """Replay decodes recorded /pearl/action and /clock CDR: garbage there is a BagError naming topic."""
    from pearl_pomdp.bags.metadata import QosProfile
    from pearl_pomdp.bags.reader import BagError, BagReader
    from pearl_pomdp.nodes.bag_replay import _clock_ns, expected_actions
    from pearl_pomdp.bags.writer import BagWriter

    with BagWriter(tmp_path / "b") as bag:
        bag.add_topic("/pearl/action", "std_msgs/msg/String", qos=[QosProfile()])
        bag.write("/pearl/action", payload, 5)
    with pytest.raises(BagError) as info:
        expected_actions(BagReader(tmp_path / "b"))
    assert "/pearl/action" in str(info.value) and str(tmp_path / "b") in str(info.value)
    if len(payload) < 12:
        with pytest.raises(ValueError):
            _clock_ns(payload)


def test_bag_info_cli_on_garbage_exits_2_with_one_line(tmp_path, capsys):
    from pearl_pomdp.cli import main

    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "bad_0.mcap").write_bytes(b"\x89MCAQ0\r\n" + b"\xff" * 40)
    for target in (bad, tmp_path / "missing", tmp_path):
        capsys.readouterr()
        code = main(["bag-info", str(target)])
        out, err = capsys.readouterr()
        assert code == 2, (target, out, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("pearl bag-info: error: "), err
