"""The commands a first run goes through: plan warns before planning
flat, saves where explain and hierarchy look, the hierarchy PNG lands under out/ and can be
read, help texts print as written, and bad inputs fail before any work starts."""
import argparse
import json
import struct
from pathlib import Path

import pytest

from pearl_pomdp.cli import build_parser, main
from test_execute import PROBE_DOMAIN, PROBE_HIERARCHY

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture
def probe(tmp_path, monkeypatch):
    """A two-state domain in an empty working directory (the default out/ goes there)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "probe.domain.yaml").write_text(PROBE_DOMAIN)
    return tmp_path


def _forbid_planning(monkeypatch):
    import pearl_pomdp.hierarchy as hierarchy_package

    def no_plan(*_args, **_kwargs):
        raise AssertionError("planned again although a saved policy was given or found")

    monkeypatch.setattr(hierarchy_package, "plan", no_plan)


@pytest.fixture
def short_flat_plans(monkeypatch):
    """Record which hierarchies are planned (the flat one is the built-in point-based plan: a
    fraction of a second on the probe; it was a 30 s exact solve before issue 21)."""
    import pearl_pomdp.hierarchy as hierarchy_package

    real_plan = hierarchy_package.plan
    seen = []

    def plan(domain, hierarchy, **kwargs):
        seen.append(hierarchy.name)
        if hierarchy.name == "flat":
            root = hierarchy.subtasks[hierarchy.root]
            assert root.children == list(domain.actions)
            assert root.solver == "pointbased" and root.horizon is None   # never a truncated exact solve
        return real_plan(domain, hierarchy, **kwargs)

    monkeypatch.setattr(hierarchy_package, "plan", plan)
    return seen


# ------------------------------------------------------------------ item 2
def test_plan_without_a_hierarchy_says_which_file_it_looked_for(probe, capsys, short_flat_plans):
    assert main(["plan", "probe.domain.yaml", "--json", "--no-save"]) == 0
    captured = capsys.readouterr()
    assert captured.err.startswith("pearl plan: warning: no --hierarchy given and no probe.hierarchy.yaml beside "
                                   "the domain: planning flat")
    assert "--flat" in captured.err
    report = json.loads(captured.out)
    assert report["hierarchy"] == "flat" and report["hierarchy_file"] is None and report["out"] is None
    assert short_flat_plans == ["flat"]


def test_plan_flat_on_purpose_or_with_the_sibling_hierarchy_does_not_warn(probe, capsys, short_flat_plans):
    assert main(["plan", "probe.domain.yaml", "--json", "--no-save", "--flat"]) == 0
    captured = capsys.readouterr()
    assert captured.err == "" and json.loads(captured.out)["hierarchy"] == "flat"
    (probe / "probe.hierarchy.yaml").write_text(PROBE_HIERARCHY)
    assert main(["plan", "probe.domain.yaml", "--json", "--no-save"]) == 0
    captured = capsys.readouterr()
    assert "planning flat" not in captured.err   # (the probe's local-reward warning may be there)
    assert json.loads(captured.out)["hierarchy_file"] == "probe.hierarchy.yaml"
    assert short_flat_plans == ["flat", "probe.hierarchy"]


def test_a_refit_domain_plans_with_the_hierarchy_of_the_name_it_declares(probe, capsys, short_flat_plans):
    """``probe_day.domain.yaml`` (a refit that declares ``name: probe``) finds ``probe.hierarchy.yaml``."""
    import re

    (probe / "probe.hierarchy.yaml").write_text(PROBE_HIERARCHY)
    declared = re.search(r"^name:\s*(\S+)", PROBE_DOMAIN, re.M).group(1)
    assert declared == "probe"
    (probe / "probe_day.domain.yaml").write_text(PROBE_DOMAIN)
    assert main(["plan", "probe_day.domain.yaml", "--json", "--no-save"]) == 0
    captured = capsys.readouterr()
    assert "planning flat" not in captured.err
    assert json.loads(captured.out)["hierarchy_file"] == "probe.hierarchy.yaml"
    assert short_flat_plans == ["probe.hierarchy"]


def test_plan_rejects_a_missing_hierarchy_file_before_planning(probe, capsys):
    assert main(["plan", "probe.domain.yaml", "--hierarchy", "nope.yaml"]) == 2
    assert capsys.readouterr().err == "pearl plan: error: nope.yaml: no such hierarchy file (--hierarchy)\n"


# ------------------------------------------------------------------ item 3
def test_plan_saves_where_explain_and_hierarchy_find_it(probe, capsys, monkeypatch):
    (probe / "probe.hierarchy.yaml").write_text(PROBE_HIERARCHY)
    assert main(["explain", "probe.domain.yaml", "--belief", "Goal=b"]) == 2
    err = capsys.readouterr().err
    assert "out/policies/probe: no policy planned for probe.domain.yaml here; run `pearl plan probe.domain.yaml`" in err

    assert main(["plan", "probe.domain.yaml"]) == 0
    assert capsys.readouterr().out.rstrip().endswith("saved to out/policies/probe")
    assert (probe / "out" / "policies" / "probe" / "hierarchy.json").is_file()

    _forbid_planning(monkeypatch)
    assert main(["explain", "probe.domain.yaml", "--belief", "Goal=b", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["action_name"] == "DoB" and [t["subtask"] for t in out["trace"]] == ["Top", "Do"]
    assert main(["hierarchy", "probe.domain.yaml"]) == 0          # sizes from the saved plan
    assert "S 2→2" in capsys.readouterr().out


# ------------------------------------------------------------------ item 4
def _png_size(path: Path):
    head = path.read_bytes()[:24]
    assert head[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", head[16:24])


def test_hierarchy_png_goes_under_out_with_its_full_path_printed(probe, capsys, monkeypatch):
    (probe / "probe.hierarchy.yaml").write_text(PROBE_HIERARCHY)
    assert main(["plan", "probe.domain.yaml", "--out", "elsewhere"]) == 0
    capsys.readouterr()
    _forbid_planning(monkeypatch)   # --policy is reused, not re-planned
    assert main(["hierarchy", "probe.domain.yaml", "--policy", "elsewhere", "--format", "png"]) == 0
    printed = capsys.readouterr().out.strip()
    assert printed == str(probe / "out" / "hierarchy-probe.png")
    assert Path(printed).is_file() and not (probe / "hierarchy.png").exists()


def test_pearl_hierarchy_png_is_screen_sized(tmp_path, pearl_policy, capsys):
    out = tmp_path / "pearl.png"
    assert main(["hierarchy", str(REPO / "config" / "pearl.domain.yaml"), "--policy", str(pearl_policy),
                 "--format", "png", "--out", str(out)]) == 0
    width, height = _png_size(out)
    # 19 primitives, one row each, at 10 pt: fits a 1366×1024 screen without shrinking (was 3211×962)
    assert width <= 1366 and height <= 1024, (width, height)
    assert width >= 900 and height >= 700   # and is not shrunk into illegibility either


def test_layout_gives_every_primitive_its_own_row():
    from pearl_pomdp.cli.hierarchy import layout
    from pearl_pomdp.hierarchy import load_hierarchy
    from pearl_pomdp.model.domain_yaml import load_domain

    domain = load_domain(REPO / "config" / "pearl.domain.yaml")
    hierarchy = load_hierarchy(REPO / "config" / "pearl.hierarchy.yaml", domain)
    nodes, edges = layout(hierarchy)
    leaves = [n for n in nodes if not n[3]]
    assert len(leaves) == 19 and sorted(y for _, y, _, _ in leaves) == [-float(i) for i in range(18, -1, -1)]
    for i, j in edges:   # children one column right of their parent
        assert nodes[j][0] == nodes[i][0] + 1


# ------------------------------------------------------------------ item 5
def _subparsers():
    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return action.choices


def test_help_texts_print_percent_signs_as_written(capsys):
    with pytest.raises(SystemExit):
        main(["experiment", "--help"])
    out = capsys.readouterr().out
    assert "95 % CIs" in out and "%%" not in out
    for name in _subparsers():
        with pytest.raises(SystemExit):
            main([name, "--help"])
        assert "%%" not in capsys.readouterr().out, name


def test_every_option_of_every_command_has_help():
    missing = [f"{name} {a.option_strings or a.dest}" for name, sub in _subparsers().items()
               for a in sub._actions if a.help is None]
    assert missing == []


def test_experiment_prints_the_noise_numbers_in_its_table(tmp_path, capsys):
    """The study's per-noise numbers are in the text table, not only in the PNG (issue 16 item 5)."""
    assert main(["experiment", "--policies", "qmdp,behaviour_tree", "--residents", "generated:1", "--episodes", "1",
                 "--noise", "0,0.5", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    report = json.loads((tmp_path / "study.json").read_text())
    rows = {(line.split()[0], line.split()[1]): line for line in out.splitlines()
            if line.split() and line.split()[0] in ("qmdp", "behaviour_tree")}
    for name in ("qmdp", "behaviour_tree"):
        for level in ("0", "0.5"):
            s = report["per_policy"][name][level]
            g = s["guidance_success"]
            assert f"{g['successes']}/{g['n']}" in rows[(name, level)]
            assert f"{s['discounted_return']['mean']:.1f}" in rows[(name, level)]


# ------------------------------------------------------------------ item 6
@pytest.mark.parametrize("argv, message", [
    (["demo", "--scenario", "/nonexistent.yaml"], "/nonexistent.yaml: no such scenario file (--scenario)"),
    (["demo", "--scenario", "/"], "/: is a directory, expected a scenario file (--scenario)"),
    (["demo", "--policy", "/nonexistent"], "/nonexistent: no such policy directory (--policy, from `pearl plan`"),
    (["solve", "/"], "/: is a directory, expected a model file (.pomdp, .pomdpx or domain .yaml)"),
    (["experiment", "--noise", "0,x"], "<command line>: --noise: '0,x': expected comma-separated numbers"),
    (["experiment", "--study", "/nonexistent.yaml"], "/nonexistent.yaml: no such study file (--study)"),
    (["experiment", "--policies", "telepathy"], "--policies: unknown policy 'telepathy'"),
])
def test_bad_inputs_fail_at_once_before_any_work(argv, message, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == ""            # no "planning the policy and starting the graph…"
    assert captured.err.startswith(f"pearl {argv[0]}: error: ") and message in captured.err
    assert not (tmp_path / "out").exists()   # nothing was created


def test_json_into_a_reader_that_left_ends_quietly(probe):
    # `pearl plan --json | head -c 50`: the pipe closes before the report is written; the command
    # ends with the shell's SIGPIPE status and no traceback (it printed two before).
    import subprocess
    import sys

    cmd = [sys.executable, "-c", "import sys; from pearl_pomdp.cli import main; sys.exit(main())",
           "plan", "probe.domain.yaml", "--flat", "--no-save", "--json"]
    proc = subprocess.Popen(cmd, cwd=probe, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()          # the reader is gone before the plan is done
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) == 141
    assert "Traceback" not in err and "BrokenPipe" not in err, err
