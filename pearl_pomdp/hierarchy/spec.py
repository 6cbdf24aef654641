"""The action hierarchy: a designer-given tree over a domain's actions (docs/design.md §4).

Pineau & Thrun partition the *action* set, not the state set: each leaf of the tree
is a primitive action of the domain (every primitive appears at least once), and each
internal node is an abstract action â_h that spans a subtask h whose actions are the
node's children (primitive or abstract).

The YAML form (``config/pearl.hierarchy.yaml`` is a complete example)::

    name: pearl                     # optional
    root: Act                       # the top subtask
    parameterize: policy            # policy (default) | corner: how a parent models a child
    defaults:                       # optional; per-subtask keys override
      solver: pointbased            # pointbased (default) | incprune (exact; subtasks of primitives)
                                    # | online (the root only: DESPOT at run time over its children)
      trials: 100                   # pointbased: trial budget (deterministic; null: until epsilon)
      epsilon: 0.01                 # pointbased: target gap at every start belief / incprune: tolerance
      horizon: null                 # incprune: epochs (null = until converged)
      lookahead: 0                  # EXECUTE: this many more steps of forward search (see below)
      expansions: 256               # ... at most this many beliefs expanded per decision
      time_limit: null              # seconds: a guard only (the budget is `trials`)
    subtasks:
      Act:
        actions: [Remind, Assist, Rest, DoNothing]   # names of subtasks or primitives
      Contact:
        actions: [RingDoorBell, GotoPatientRoom]
        shaping:                               # optional reward shaping (Dietterich 2000)
          - {action: RingDoorBell, reward: 1.0, when: {UserPresent: no}}
          # adds `reward` to R_h(s, action) in the states matching every `when` entry
          # (a value or a list of values); without `when`, in every state.

``parameterize: policy`` (the default; :mod:`pearl_pomdp.hierarchy.plan`): every subtask
but the root is an option that may stop (:mod:`pearl_pomdp.hierarchy.options`), solved for
the discounted infinite horizon over the primitives below it; a parent at a belief chooses
among the primitives its children would execute *at that belief*, valued in its own model
(policy-contingent), so it sees each child as the child acts. Shaping rules then name
primitives below the subtask. ``lookahead: d`` adds ``d`` steps of forward search over the
children's choices at execution, within ``expansions`` expanded beliefs per decision.

``solver: online`` on the root (``parameterize: policy`` only) leaves the root unplanned: at run
time it runs DESPOT over its own actions, each child resolved at every search node to the
primitive its offline policy picks there (:mod:`pearl_pomdp.hierarchy.online_root`); its
``trials`` are the search's trials per decision and ``time_limit`` a guard per decision.

``parameterize: corner`` is the paper's PARAMETERIZE (eq. 15–17): an abstract action is the
primitive its child picks at the belief concentrated on each state; the subtask is solved
to ``horizon`` by incremental pruning (or point-based), and ``lookahead: d`` makes EXECUTE
choose the subtask's action by exact forward search over its abstract model, ``d`` steps
deep, with the solved horizon-``h`` α-vectors at the leaves (see
:class:`~pearl_pomdp.policies.lookahead.Lookahead`).

A name in ``actions`` is abstract when it is a key of ``subtasks``, otherwise it must
be a primitive action of the domain. Each subtask is used once (the structure is a
tree); a primitive may appear under several subtasks.

Validation raises :class:`~pearl_pomdp.errors.SpecError` naming the file, the line and
the field path (``subtasks.Assist.actions[2]``): unknown action, abstract node with no
children, cycles, a subtask used twice or never, duplicated children, primitives of the
domain missing from the tree, unknown keys, bad solver settings.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union


from pearl_pomdp.errors import SpecError
from pearl_pomdp.model.factored import FactoredDomain

__all__ = ["Hierarchy", "SubtaskSpec", "ShapingRule", "load_hierarchy", "parse_hierarchy",
           "flat_hierarchy", "SOLVERS", "PARAMETERIZATIONS", "BUILTIN_DEFAULTS"]

#: Solver names a subtask may ask for (``online``: the root only, planned at run time by DESPOT).
SOLVERS = ("incprune", "pointbased", "online")
_SUBTASK_KEYS = {"actions", "solver", "horizon", "lookahead", "epsilon", "time_limit", "trials", "expansions",
                 "shaping", "description"}
_DEFAULT_KEYS = {"solver", "horizon", "lookahead", "epsilon", "time_limit", "trials", "expansions"}
#: How a parent models an abstract child (the hierarchy file's top-level ``parameterize``).
PARAMETERIZATIONS = ("policy", "corner")
#: Deepest forward search allowed: its cost grows as (|A|·|Z|)^d per decision.
MAX_LOOKAHEAD = 3
_TOP_KEYS = {"name", "root", "defaults", "subtasks", "description", "parameterize"}
#: The settings of a subtask the file does not set, per parameterisation (the one source of them).
BUILTIN_DEFAULTS = {
    # Policy-contingent: point-based with a deterministic trial budget, no clock.
    "policy": {"solver": "pointbased", "horizon": None, "lookahead": 0, "epsilon": 0.01, "time_limit": None,
               "trials": 100, "expansions": 256},
    # The paper's eq. 15–17: exact incremental pruning, as in the paper.
    "corner": {"solver": "incprune", "horizon": None, "lookahead": 0, "epsilon": 1e-6, "time_limit": 30.0,
               "trials": None, "expansions": 256},
}


@dataclass(frozen=True)
class ShapingRule:
    """``R_h(s, action) += reward`` in the states where every feature in ``when`` has one of its values.

    ``when`` maps a state feature name to a tuple of allowed value names (empty: all states).
    """

    action: str
    reward: float
    when: Tuple[Tuple[str, Tuple[str, ...]], ...] = ()


@dataclass
class SubtaskSpec:
    """One internal node of the tree: the subtask spanned by abstract action ``name``.

    Attributes:
        name: the abstract action / subtask name.
        children: its action set, in file order (primitive or abstract names).
        solver: ``"incprune"`` or ``"pointbased"``.
        horizon: incremental-pruning epochs (``None``: until the ε-convergence test).
        lookahead: steps of EXECUTE's forward search over the subtask model (0: none beyond
            the policy-contingent one-step choice).
        epsilon: incprune convergence tolerance, or point-based target gap.
        time_limit: seconds allowed to this subtask's solver (``None``: no clock).
        trials: point-based trial budget (``None``: until ``epsilon`` at every start belief).
        expansions: beliefs the forward search may expand per decision (``lookahead`` > 0).
        shaping: reward-shaping rules added to the subtask's reward.
    """

    name: str
    children: List[str]
    solver: str = "incprune"
    horizon: Optional[int] = None
    lookahead: int = 0
    epsilon: float = 1e-6
    time_limit: Optional[float] = 30.0
    shaping: List[ShapingRule] = field(default_factory=list)
    description: str = ""
    trials: Optional[int] = None
    expansions: int = 256


@dataclass
class Hierarchy:
    """A validated action hierarchy.

    Attributes:
        name: a label.
        root: the top subtask's name.
        subtasks: subtask name → :class:`SubtaskSpec`.
        primitives: the domain's primitive action names, in domain order.
        source: the file it came from (for messages).
    """

    name: str
    root: str
    subtasks: Dict[str, SubtaskSpec]
    primitives: List[str]
    source: str = "<hierarchy>"
    #: ``"policy"`` (policy-contingent parents, options) or ``"corner"`` (eq. 15–17).
    parameterize: str = "policy"

    def is_abstract(self, name: str) -> bool:
        """True when ``name`` is a subtask (abstract action), False for a primitive."""
        return name in self.subtasks

    def postorder(self) -> List[str]:
        """Subtask names children-first (the order PLAN solves them), root last."""
        out: List[str] = []

        def visit(name: str) -> None:
            for child in self.subtasks[name].children:
                if child in self.subtasks:
                    visit(child)
            out.append(name)

        visit(self.root)
        return out

    def parent_of(self, name: str) -> Optional[str]:
        """The subtask whose action set contains abstract action ``name`` (``None`` for the root)."""
        for spec in self.subtasks.values():
            if name in spec.children:
                return spec.name
        return None

    def descendants(self, name: str) -> List[str]:
        """Every primitive below subtask ``name`` (each once, in tree order)."""
        seen: List[str] = []
        for child in self.subtasks[name].children:
            for p in (self.descendants(child) if child in self.subtasks else [child]):
                if p not in seen:
                    seen.append(p)
        return seen

    def depth(self, name: str) -> int:
        """0 for the root, 1 for its abstract children, ..."""
        d, parent = 0, self.parent_of(name)
        while parent is not None:
            d, parent = d + 1, self.parent_of(parent)
        return d


# --------------------------------------------------------------------- YAML with lines
def _compose(text: str, source: str):
    """Parse YAML with the one line-aware loader (:mod:`pearl_pomdp.yaml_lines`): data plus
    ``{field.path: line}`` (1-based)."""
    from pearl_pomdp.yaml_lines import line_table, parse_yaml

    data = parse_yaml(text, source)
    if data is None:
        raise SpecError(source, "", "the file is empty; expected a mapping with 'root' and 'subtasks'")
    return data, line_table(data)


class _Checker:
    def __init__(self, source: str, lines: Mapping[str, int]):
        self.source, self.lines = source, lines

    def fail(self, where: str, problem: str) -> SpecError:
        line = self.lines.get(where)
        probe = where
        while line is None and probe:
            probe = probe.rsplit(".", 1)[0] if "." in probe else (probe.rsplit("[", 1)[0] if "[" in probe else "")
            line = self.lines.get(probe)
        return SpecError(self.source, where, problem, line=line)


def _setting(chk: _Checker, where: str, key: str, value):
    if key == "solver":
        if value not in SOLVERS:
            raise chk.fail(where, f"unknown solver {value!r}; expected one of: {', '.join(SOLVERS)}")
        return value
    if key == "horizon":
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise chk.fail(where, f"horizon must be a positive integer or null, got {value!r}")
        return int(value)
    if key == "lookahead":
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_LOOKAHEAD:
            raise chk.fail(where, f"lookahead must be an integer from 0 to {MAX_LOOKAHEAD} (steps of forward "
                                  f"search), got {value!r}")
        return int(value)
    if key in ("trials", "expansions"):
        if value is None and key == "trials":
            return None
        if isinstance(value, bool) or not isinstance(value, int) or value < (0 if key == "expansions" else 1):
            raise chk.fail(where, f"{key} must be {'a non-negative' if key == 'expansions' else 'a positive'} "
                                  f"integer{' or null' if key == 'trials' else ''}, got {value!r}")
        return int(value)
    if key in ("epsilon", "time_limit"):
        if value is None and key == "time_limit":
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
            raise chk.fail(where, f"{key} must be a positive number, got {value!r}")
        return float(value)
    raise chk.fail(where, f"unknown setting {key!r}")


def parse_hierarchy(text: str, primitives: Sequence[str], features: Optional[Mapping[str, Sequence[str]]] = None,
                    source: str = "<string>") -> Hierarchy:
    """Parse and validate hierarchy YAML against a domain's actions (and features, for shaping).

    Args:
        text: the YAML text.
        primitives: the domain's primitive action names.
        features: state feature name → value names (checks ``shaping.when``); ``None`` skips that check.
        source: file name for messages.

    Raises:
        SpecError: naming the file, line and field path of the first problem.
    """
    data, lines = _compose(text, source)
    chk = _Checker(source, lines)
    if not isinstance(data, dict):
        raise chk.fail("", f"expected a mapping with 'root' and 'subtasks', got {type(data).__name__}")
    for key in data:
        if key not in _TOP_KEYS:
            raise chk.fail(key, f"unknown key; expected one of: {', '.join(sorted(_TOP_KEYS))}")
    raw_subtasks = data.get("subtasks")
    if not isinstance(raw_subtasks, dict) or not raw_subtasks:
        raise chk.fail("subtasks", "missing or empty: expected a mapping of subtask name → {actions: [...]}")
    parameterize = data.get("parameterize", "policy")
    if parameterize not in PARAMETERIZATIONS:
        raise chk.fail("parameterize", f"unknown parameterisation {parameterize!r}; expected one of: "
                                       f"{', '.join(PARAMETERIZATIONS)}")
    defaults = dict(BUILTIN_DEFAULTS[parameterize])
    raw_defaults = data.get("defaults") or {}
    if not isinstance(raw_defaults, dict):
        raise chk.fail("defaults", "expected a mapping")
    for key, value in raw_defaults.items():
        if key not in _DEFAULT_KEYS:
            raise chk.fail(f"defaults.{key}", f"unknown key; expected one of: {', '.join(sorted(_DEFAULT_KEYS))}")
        defaults[key] = _setting(chk, f"defaults.{key}", key, value)
    prim_set = set(primitives)
    subtasks: Dict[str, SubtaskSpec] = {}
    for name in raw_subtasks:
        if name in prim_set:
            raise chk.fail(f"subtasks.{name}", f"subtask name {name!r} is also a primitive action of the domain; "
                                               "rename the subtask")
    for name, body in raw_subtasks.items():
        where = f"subtasks.{name}"
        if body is None or isinstance(body, list):
            body = {"actions": body}
        if not isinstance(body, dict):
            raise chk.fail(where, "expected a mapping with 'actions'")
        for key in body:
            if key not in _SUBTASK_KEYS:
                raise chk.fail(f"{where}.{key}", f"unknown key; expected one of: {', '.join(sorted(_SUBTASK_KEYS))}")
        children = body.get("actions")
        if not children:
            raise chk.fail(f"{where}.actions" if "actions" in body else where,
                           "abstract action has no children: list at least one action under 'actions'")
        if not isinstance(children, list):
            raise chk.fail(f"{where}.actions", f"expected a list of action names, got {type(children).__name__}")
        seen = set()
        for i, child in enumerate(children):
            cw = f"{where}.actions[{i}]"
            if not isinstance(child, str):
                raise chk.fail(cw, f"expected an action name, got {child!r}")
            if child in seen:
                raise chk.fail(cw, f"duplicate action {child!r} in subtask {name!r}")
            seen.add(child)
            if child not in prim_set and child not in raw_subtasks:
                raise chk.fail(cw, f"unknown action {child!r}: neither a primitive of the domain nor a subtask "
                                   f"(subtasks: {', '.join(raw_subtasks)})")
        settings: Dict[str, Any] = dict(defaults)
        for key in sorted(_DEFAULT_KEYS):
            if key in body:
                settings[key] = _setting(chk, f"{where}.{key}", key, body[key])
        shaping = _parse_shaping(chk, f"{where}.shaping", body.get("shaping"), children, features,
                                 list(primitives) if parameterize == "policy" else ())
        subtasks[name] = SubtaskSpec(name=name, children=list(children), shaping=shaping,
                                     description=str(body.get("description", "")), **settings)

    root = data.get("root")
    if root is None:
        # A single subtask nobody references is the obvious root.
        referenced = {c for s in subtasks.values() for c in s.children}
        roots = [n for n in subtasks if n not in referenced]
        if len(roots) != 1:
            raise chk.fail("root", f"missing; set it to the top subtask (candidates: {', '.join(roots) or 'none'})")
        root = roots[0]
    if root not in subtasks:
        raise chk.fail("root", f"root {root!r} is not a subtask (subtasks: {', '.join(subtasks)})")

    # Tree checks: every subtask reached exactly once from the root, no cycles.
    used_at: Dict[str, str] = {}

    def walk(name: str, stack: List[str]) -> None:
        for i, child in enumerate(subtasks[name].children):
            if child not in subtasks:
                continue
            cw = f"subtasks.{name}.actions[{i}]"
            if child in stack or child == name:
                cycle = " → ".join(stack + [name, child])
                raise chk.fail(cw, f"cycle in the hierarchy: {cycle}")
            if child == root:
                raise chk.fail(cw, f"the root subtask {root!r} cannot be a child")
            if child in used_at:
                raise chk.fail(cw, f"subtask {child!r} is used twice (also at {used_at[child]}); "
                                   "the hierarchy is a tree: define a second subtask with another name")
            used_at[child] = cw
            walk(child, stack + [name])

    walk(root, [])
    for name in subtasks:
        if name != root and name not in used_at:
            raise chk.fail(f"subtasks.{name}", f"subtask {name!r} is not reachable from the root {root!r}")
    hierarchy = Hierarchy(name=str(data.get("name", Path(source).stem)), root=root, subtasks=subtasks,
                          primitives=list(primitives), source=source, parameterize=parameterize)
    if parameterize == "policy":
        _check_policy_settings(chk, hierarchy)
    else:
        for name, spec in subtasks.items():
            if spec.solver == "online":
                raise chk.fail(f"subtasks.{name}.solver" if "solver" in (raw_subtasks[name] or {}) else "defaults.solver",
                               "solver online needs parameterize: policy (an online root consults its children's "
                               "policy-contingent picks; corner children have none)")
    covered = set(hierarchy.descendants(root))
    missing = [p for p in primitives if p not in covered]
    if missing:
        raise chk.fail("subtasks", f"primitive action(s) missing from the tree: {', '.join(missing)} "
                                   "(every primitive must appear at least once)")
    return hierarchy


def _check_policy_settings(chk: _Checker, hierarchy: Hierarchy) -> None:
    """What policy-contingent planning cannot do: incremental pruning of a parent (its
    children's picks depend on the belief, which only a point-based solver sees), and shaping
    of an abstract action (the parent's actions are the primitives below it)."""
    for name, spec in hierarchy.subtasks.items():
        where = f"subtasks.{name}"
        abstract = [c for c in spec.children if c in hierarchy.subtasks]
        if spec.solver == "online":
            if name != hierarchy.root:
                raise chk.fail(f"{where}.solver", f"only the root ({hierarchy.root!r}) can plan online: {name!r} is a "
                                                  f"child of {hierarchy.parent_of(name)!r}, which consults its offline "
                                                  "policy (a 'solver: online' under defaults makes every subtask online)")
            if spec.trials is None and spec.time_limit is None:
                raise chk.fail(f"{where}.trials", "an online root needs trials (DESPOT trials per decision) or a "
                                                  "time_limit (seconds per decision)")
            if spec.horizon is not None:
                raise chk.fail(f"{where}.horizon", "an online root has no horizon of its own (DESPOT's depth bounds "
                                                   "its search); remove horizon")
            if spec.lookahead:
                raise chk.fail(f"{where}.lookahead", "lookahead is EXECUTE's search over an offline policy; an online "
                                                     "root searches by itself (its depth is DESPOT's)")
            if spec.shaping:
                raise chk.fail(f"{where}.shaping", "an online root plans with the domain's own rewards: shaping is for "
                                                   "offline subtasks")
            continue
        if spec.solver == "incprune" and abstract:
            raise chk.fail(f"{where}.solver", f"incprune cannot solve {name!r}: it has abstract children "
                                              f"({', '.join(abstract)}), whose picks depend on the belief; use "
                                              "pointbased (or parameterize: corner, the paper's eq. 15-17)")
        if spec.solver == "pointbased" and spec.horizon is not None:
            raise chk.fail(f"{where}.horizon", "a finite horizon applies to incprune only (pointbased solves the "
                                               "discounted infinite horizon)")
        if spec.solver == "pointbased" and spec.trials is None and spec.time_limit is None and not spec.epsilon > 0:
            raise chk.fail(f"{where}.trials", "with trials: null give an epsilon > 0 or a time_limit")
        below = hierarchy.descendants(name)
        for i, rule in enumerate(spec.shaping):
            if rule.action not in below:
                raise chk.fail(f"{where}.shaping[{i}].action",
                               f"{rule.action!r} is not a primitive below {name!r}; with parameterize: policy a "
                               f"subtask's actions are the primitives below it ({', '.join(below)})")


def _parse_shaping(chk: _Checker, where: str, raw, children: Sequence[str],
                   features: Optional[Mapping[str, Sequence[str]]],
                   descendants: Sequence[str] = ()) -> List[ShapingRule]:
    if raw is None:
        return []
    if not isinstance(raw, list):
        raise chk.fail(where, "expected a list of {action, reward, when} rules")
    rules = []
    for i, rule in enumerate(raw):
        rw = f"{where}[{i}]"
        if not isinstance(rule, dict):
            raise chk.fail(rw, "expected a mapping {action, reward, when}")
        for key in rule:
            if key not in ("action", "reward", "when"):
                raise chk.fail(f"{rw}.{key}", "unknown key; expected action, reward, when")
        action = rule.get("action")
        if action not in children and action not in descendants:
            raise chk.fail(f"{rw}.action", f"{action!r} is not an action of this subtask ({', '.join(children)})")
        reward = rule.get("reward")
        if isinstance(reward, bool) or not isinstance(reward, (int, float)):
            raise chk.fail(f"{rw}.reward", f"expected a number, got {reward!r}")
        when = rule.get("when") or {}
        if not isinstance(when, dict):
            raise chk.fail(f"{rw}.when", "expected a mapping feature → value(s)")
        conds = []
        for feat, vals in when.items():
            fw = f"{rw}.when.{feat}"
            vals = [vals] if not isinstance(vals, list) else vals
            vals = [v if isinstance(v, str) else _yaml_scalar_name(v) for v in vals]
            if features is not None:
                if feat not in features:
                    raise chk.fail(fw, f"unknown state feature {feat!r}; known: {', '.join(features)}")
                for v in vals:
                    if v not in features[feat]:
                        raise chk.fail(fw, f"unknown value {v!r} of {feat}; expected one of: {', '.join(features[feat])}")
            conds.append((feat, tuple(vals)))
        rules.append(ShapingRule(action=str(action), reward=float(reward), when=tuple(conds)))
    return rules


def _yaml_scalar_name(value) -> str:
    # YAML 1.1 reads yes/no as booleans; feature values such as UserPresent {yes, no} are names.
    if value is True:
        return "yes"
    if value is False:
        return "no"
    return str(value)


def load_hierarchy(path: Union[str, Path], domain) -> Hierarchy:
    """Load and validate a hierarchy file against ``domain``.

    Args:
        path: the YAML file.
        domain: a :class:`~pearl_pomdp.model.factored.FactoredDomain` (actions and features are
            checked) or a flat :class:`~pearl_pomdp.model.pomdp.Pomdp` (actions only).

    Raises:
        SpecError: the file is invalid (names file, line and field).
        FileNotFoundError: no such file.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(2, "no such hierarchy file", str(path))
    features = None
    if isinstance(domain, FactoredDomain):
        features = {f.name: list(f.values) for f in domain.features}
    return parse_hierarchy(path.read_text(), list(domain.actions), features, source=str(path))


def flat_hierarchy(primitives: Sequence[str], root: str = "Root", parameterize: str = "policy",
                   **settings) -> Hierarchy:
    """A one-level hierarchy (root → every primitive): the flat problem in hierarchy form."""
    spec = SubtaskSpec(name=root, children=list(primitives), **{**BUILTIN_DEFAULTS[parameterize], **settings})
    return Hierarchy(name="flat", root=root, subtasks={root: spec}, primitives=list(primitives),
                     parameterize=parameterize)
