"""The import structure of pearl_pomdp, read from the source with ``ast`` (nothing is imported):
no import circle, nothing ``interfaces.py`` leans on sits above it, no private name imported
from another module. Every import counts: module level, inside functions and under
``TYPE_CHECKING`` (a circle through a typing import is still two modules that need each other).
"""
from __future__ import annotations

import ast
from pathlib import Path
from typing import Dict, List, Optional, Set

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "pearl_pomdp"


def module_files(package: Path) -> Dict[str, Path]:
    """Dotted module name → source file, for every ``.py`` under ``package``."""
    out = {}
    for path in sorted(package.rglob("*.py")):
        parts = list(path.relative_to(package.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def is_submodule(package: Path, dotted: str) -> bool:
    """Whether ``dotted`` names a module of the package on disk (source, C extension or stub)."""
    base = package.parent.joinpath(*dotted.split("."))
    return base.is_dir() or any(base.with_suffix(s).is_file() for s in (".py", ".pyi", ".c"))


def imports(package: Path) -> Dict[str, List[tuple]]:
    """Per module, its imports of the package: ``(imported module, name or None, line)``."""
    modules = module_files(package)
    top = package.name
    out: Dict[str, List[tuple]] = {}
    for name, path in modules.items():
        found = out.setdefault(name, [])
        here = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, ast.Import):
                found.extend((a.name, None, node.lineno) for a in node.names if a.name.split(".")[0] == top)
            elif isinstance(node, ast.ImportFrom):
                base = ".".join(here[:len(here) - node.level + 1] + ([node.module] if node.module else [])) \
                    if node.level else (node.module or "")
                if base.split(".")[0] == top:
                    found.extend((base, a.name, node.lineno) for a in node.names)
    return out


def graph(package: Path) -> Dict[str, Set[str]]:
    """Module → the package's modules it imports (``from pkg import sub`` is an import of ``pkg.sub``)."""
    modules = module_files(package)

    def owner(dotted: str) -> Optional[str]:
        while dotted and dotted not in modules:
            dotted = dotted.rpartition(".")[0]
        return dotted or None

    edges: Dict[str, Set[str]] = {m: set() for m in modules}
    for m, found in imports(package).items():
        for base, name, _ in found:
            target = owner(f"{base}.{name}" if name else base)
            if target and target != m:
                edges[m].add(target)
    return edges


def circles(edges: Dict[str, Set[str]]) -> List[List[str]]:
    """One circle ``[a, b, …, a]`` per module that lies on one, found by depth-first search."""
    found, state = [], {}   # state: 1 on the path, 2 done

    def visit(m: str, path: List[str]) -> None:
        state[m] = 1
        for t in sorted(edges[m]):
            if state.get(t) == 1:
                found.append(path[path.index(t):] + [t])
            elif t not in state:
                visit(t, path + [t])
        state[m] = 2

    for m in sorted(edges):
        if m not in state:
            visit(m, [m])
    return found


def unit(module: str) -> str:
    """The layer a module belongs to: its first-level subpackage, or itself (``pearl_pomdp.x``)."""
    return ".".join(module.split(".")[:2])


def upward_from(edges: Dict[str, Set[str]], module: str) -> List[str]:
    """What ``module`` leans on (its imports, followed through) that sits in a layer importing ``module``."""
    above = {unit(m) for m, targets in edges.items() if module in targets}
    reached, todo = set(), [module]
    while todo:
        for t in edges[todo.pop()] - reached:
            reached.add(t)
            todo.append(t)
    return sorted(m for m in reached if unit(m) in above)


def private_imports(package: Path) -> List[str]:
    """``module:line: from x import _y`` for every private name (not a module, not a dunder) taken from another module."""
    return [f"{m}:{line}: from {base} import {name}" for m, found in imports(package).items()
            for base, name, line in found
            if name and name.startswith("_") and not name.startswith("__") and base != m
            and not is_submodule(package, f"{base}.{name}")]


def test_pearl_pomdp_has_no_import_circle():
    assert circles(graph(PACKAGE)) == []


def test_interfaces_lean_on_nothing_above_them():
    assert upward_from(graph(PACKAGE), "pearl_pomdp.interfaces") == []


def test_no_private_name_is_imported_from_another_module():
    assert private_imports(PACKAGE) == []


@pytest.fixture
def tangled(tmp_path: Path) -> Path:
    """A small package with each fault once: a circle through a function-level and a typing import,
    interfaces importing from a layer that imports them, a private name taken across modules."""
    files = {
        "__init__.py": "",
        "interfaces.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pearl_pomdp.solvers.base import R\n",
        "solvers/__init__.py": "",
        "solvers/base.py": "R = 1\n",
        "solvers/registry.py": "from pearl_pomdp.interfaces import Solver\nfrom . import _kernel\n",
        "solvers/_kernel.c": "",
        "a.py": "def f():\n    from pearl_pomdp.b import g\n",
        "b.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pearl_pomdp import a\n"
                "from pearl_pomdp.solvers.base import _hidden, __doc__\n",
    }
    for rel, text in files.items():
        path = tmp_path / "pearl_pomdp" / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return tmp_path / "pearl_pomdp"


def test_the_checks_find_each_fault_in_a_tangled_package(tangled):
    edges = graph(tangled)
    assert circles(edges) == [["pearl_pomdp.a", "pearl_pomdp.b", "pearl_pomdp.a"]]
    assert upward_from(edges, "pearl_pomdp.interfaces") == ["pearl_pomdp.solvers.base"]
    # The C kernel is a private module, not a name; a dunder is not private.
    assert private_imports(tangled) == ["pearl_pomdp.b:4: from pearl_pomdp.solvers.base import _hidden"]
