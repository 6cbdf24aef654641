"""Security (issue 7): no code execution from user files, and a user file cannot make the
process read or write anything the user did not name.

* The package source is scanned (AST, not text, so a docstring saying "pickle" is no hit):
  no pickle/marshal/shelve/dill, no eval/exec/compile of strings, no ``yaml.load`` /
  ``yaml.unsafe_load`` / ``yaml.full_load`` (only SafeLoader-based loaders), no
  ``np.load`` with pickles allowed, no ``shell=True``, no ``os.system``/``os.popen``.
* Domain, hierarchy, scenario and policy readers are run under a Python audit hook: while they
  parse a file full of paths, ``include:``/``from:`` keys and ``../`` names, the only file
  opened is the one the user named, and nothing is written.
"""
from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

from pearl_pomdp.errors import PearlError, SpecError

REPO = Path(__file__).resolve().parents[1]
PACKAGES = [REPO / "pearl_pomdp", REPO / "pearl_sim"]
SOURCES = sorted(p for pkg in PACKAGES for p in pkg.rglob("*.py"))

BANNED_MODULES = {"pickle", "cPickle", "_pickle", "marshal", "shelve", "dill", "cloudpickle", "joblib"}
BANNED_CALLS = {"eval", "exec", "compile", "execfile", "input"}
UNSAFE_YAML = {"load", "load_all", "unsafe_load", "unsafe_load_all", "full_load", "full_load_all"}
SAFE_LOADERS = ("SafeLoader", "CSafeLoader", "BaseLoader", "_Loader")


def _dotted(node) -> str:
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if isinstance(node, ast.Name):
        parts.append(node.id)
    else:
        parts.append("<expr>")  # x().compile() is a method, not the builtin
    return ".".join(reversed(parts))


def scan(path: Path):
    """Every dangerous construct in ``path``: ``[(line, what)]``."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    hits = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            hits += [(node.lineno, f"import {a.name}") for a in node.names if a.name.split(".")[0] in BANNED_MODULES]
        elif isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] in BANNED_MODULES:
            hits.append((node.lineno, f"from {node.module} import"))
        elif isinstance(node, ast.Call):
            name = _dotted(node.func)
            kw = {k.arg: k.value for k in node.keywords}
            if name in BANNED_CALLS:
                hits.append((node.lineno, f"{name}()"))
            if name in ("os.system", "os.popen", "os.execl", "os.spawnl") or name.startswith("pickle."):
                hits.append((node.lineno, f"{name}()"))
            if name.startswith("yaml.") and name.split(".")[-1] in UNSAFE_YAML:
                loader = kw.get("Loader") or (node.args[1] if len(node.args) > 1 else None)
                text = ast.unparse(loader) if loader is not None else "default"
                if loader is None or not (_dotted(loader).endswith(SAFE_LOADERS) or
                                          ("SafeLoader" in text and "UnsafeLoader" not in text)):
                    hits.append((node.lineno, f"{name}() with loader {text}"))
            if "allow_pickle" in kw and not (isinstance(kw["allow_pickle"], ast.Constant) and kw["allow_pickle"].value is False):
                hits.append((node.lineno, f"{name}(allow_pickle=…)"))
            if "shell" in kw and not (isinstance(kw["shell"], ast.Constant) and kw["shell"].value is False):
                hits.append((node.lineno, f"{name}(shell=…)"))
    return hits


def test_scanner_finds_what_it_looks_for(tmp_path):
    """The scanner itself: each banned construct in a sample file is reported."""
    sample = tmp_path / "bad.py"
    sample.write_text("import pickle\nfrom marshal import loads\nimport yaml, numpy as np, subprocess, os\n"
                      "eval('1')\nexec('x=1')\nyaml.load(t)\nyaml.load(t, Loader=yaml.Loader)\n"
                      "yaml.load(t, Loader=yaml.SafeLoader)\nyaml.full_load(t)\nnp.load(f, allow_pickle=True)\n"
                      "subprocess.run(c, shell=True)\nsubprocess.run(c, shell=False)\nos.system('x')\n")
    lines = sorted(line for line, _ in scan(sample))
    assert lines == [1, 2, 4, 5, 6, 7, 9, 10, 11, 13]


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(REPO)))
def test_no_code_execution_constructs(path):
    assert scan(path) == []


def test_every_yaml_reader_is_safe():
    """Every YAML parse call in the package names a SafeLoader-derived loader or is safe_load."""
    calls = []
    for path in SOURCES:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Call) and _dotted(node.func).startswith("yaml."):
                calls.append((path.name, _dotted(node.func)))
    assert calls, "expected YAML readers in the package"
    unsafe = [c for c in calls if c[1].split(".")[-1] in UNSAFE_YAML | {"load"}]
    assert not [c for c in unsafe if c[1] in ("yaml.unsafe_load", "yaml.full_load")], unsafe
    from pearl_pomdp.yaml_lines import _Loader  # the one YAML loader (domain, hierarchy, scenario, params)

    import yaml

    assert issubclass(_Loader, yaml.SafeLoader)


# ------------------------------------------------------------------ file access while parsing
_EVENTS: list = []
_RECORDING = [False]


def _hook(event, args):
    if _RECORDING[0] and event in ("open", "os.remove", "os.rename", "os.mkdir", "shutil.rmtree", "os.symlink",
                                   "subprocess.Popen", "os.system", "os.exec", "os.posix_spawn"):
        _EVENTS.append((event, args[0] if args else None, args[1] if len(args) > 1 else None))


sys.addaudithook(_hook)  # hooks cannot be removed; it records only inside `recorded()`


class recorded:
    def __enter__(self):
        _EVENTS.clear()
        _RECORDING[0] = True
        return _EVENTS

    def __exit__(self, *exc):
        _RECORDING[0] = False


EVIL_DOMAIN = """name: ../../etc/passwd
include: /etc/passwd
from: ../../../../etc/shadow
features:
  - name: /etc/hosts
    values: [/etc/passwd, ../secret, "$(cat /etc/passwd)"]
actions:
  - name: ~/.ssh/id_rsa
"""


def test_domain_file_reads_only_itself(tmp_path):
    from pearl_pomdp.model.domain_yaml import load_domain

    f = tmp_path / "evil.domain.yaml"
    f.write_text(EVIL_DOMAIN)
    with recorded() as events:
        with pytest.raises(SpecError) as info:
            load_domain(f)
    assert str(info.value).startswith(str(f))
    opened = [e for e in events if e[0] == "open"]
    assert [Path(str(e[1])) for e in opened] == [f], events
    assert all(e[0] == "open" for e in events), events
    assert all(e[2] in (None, "r", "rb") for e in opened), events


def test_hierarchy_and_scenario_files_read_only_themselves(tmp_path):
    from pearl_pomdp.hierarchy.spec import load_hierarchy
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.nursing_home.scenario import load_scenarios

    domain = load_domain(REPO / "config" / "pearl.domain.yaml")
    h = tmp_path / "evil.hierarchy.yaml"
    h.write_text("include: /etc/passwd\nroot: /etc/passwd\nsubtasks:\n  /etc/passwd:\n    children: [../x]\n")
    s = tmp_path / "evil.scenario.yaml"
    s.write_text("name: x\nfrom: /etc/passwd\ninclude: [/etc/shadow]\nmap: /etc/passwd\n")
    for f, load in ((h, lambda p: load_hierarchy(p, domain)), (s, load_scenarios)):
        with recorded() as events:
            with pytest.raises(SpecError) as info:
                load(f)
        assert str(info.value).startswith(str(f)), str(info.value)
        assert [Path(str(e[1])) for e in events] == [f], events


def test_shipped_configs_read_only_themselves():
    """The real files load while opening nothing but themselves."""
    from pearl_pomdp.hierarchy.spec import load_hierarchy
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.nursing_home.scenario import load_scenarios

    d = REPO / "config" / "pearl.domain.yaml"
    h = REPO / "config" / "pearl.hierarchy.yaml"
    s = REPO / "config" / "scenarios" / "study.yaml"
    # Warm every lazy import outside the recording (loading a scenario imports the speech
    # channel's modules on first use): run alone, this test would otherwise see their files.
    load_scenarios(s)
    load_hierarchy(h, load_domain(d))
    with recorded() as events:
        domain = load_domain(d)
        load_hierarchy(h, domain)
        load_scenarios(s)
    assert [Path(str(e[1])) for e in events] == [d, h, s], events


def test_policy_header_cannot_point_elsewhere(tmp_path):
    """A policy header naming other files (../, absolute) is not followed: only PATH and PATH.json are read."""
    import json

    import numpy as np

    from pearl_pomdp.errors import PolicyError
    from pearl_pomdp.model.pomdp_format import parse_pomdp
    from pearl_pomdp.policy_io import load_policy, save_policy
    from pearl_pomdp.solution import AlphaVectorPolicy

    model = parse_pomdp("discount: 0.9\nvalues: reward\nstates: 2\nactions: 2\nobservations: 2\n"
                        "T: * identity\nO: * uniform\nR: 0 : * : * : * 1\n", source="m.pomdp")
    p = save_policy(tmp_path / "p.npz", AlphaVectorPolicy(np.eye(2), np.array([0, 1])), model, {})
    header = tmp_path / "p.json"
    doc = json.loads(header.read_text())
    for key in ("npz", "file", "path", "arrays", "model_path"):
        doc[key] = "/etc/passwd"
    header.write_text(json.dumps(doc))
    with recorded() as events:
        try:
            load_policy(p, model)
        except PolicyError:
            pass
    opened = {Path(str(e[1])).resolve() for e in events if e[0] == "open" and isinstance(e[1], (str, Path))
              and not str(e[1]).endswith((".py", ".pyc"))}  # lazily imported modules (zipfile's codecs)
    assert opened <= {p.resolve(), header.resolve()}, opened
    assert not [e for e in events if e[0] != "open"], events


def test_launch_param_from_resolves_relative_to_launch_file_or_cwd(tmp_path, monkeypatch):
    """Documented (docs/reliability.md): ``<param from=F>`` reads F as given (cwd) if it exists, else
    beside the launch file; a missing file is an error naming the launch file — it never searches."""
    from pearl_pomdp.launch_xml import parse_launch_file as load_launch

    sub = tmp_path / "launch"
    sub.mkdir()
    (sub / "p.yaml").write_text("x:\n  ros__parameters:\n    a: 1\n")
    launch = sub / "l.launch.xml"
    launch.write_text('<launch><node pkg="pearl_pomdp" exec="belief_tracker" name="x">'
                      '<param from="p.yaml"/></node></launch>')
    monkeypatch.chdir(tmp_path)
    nodes = load_launch(launch).nodes
    params = [p for n in nodes for p in n.parameters if p[0] == "file"]
    assert params == [("file", str((sub / "p.yaml").resolve()))]
    launch.write_text('<launch><node pkg="pearl_pomdp" exec="belief_tracker" name="x">'
                      '<param from="../../nope/p.yaml"/></node></launch>')
    with pytest.raises(PearlError) as info:
        load_launch(launch)
    assert str(launch) in str(info.value) and "no such parameters file" in str(info.value)
