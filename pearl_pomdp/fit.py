"""``pearl fit``: the domain's transition and observation tables estimated from recorded episodes.

HRI researchers record sessions; this is how their model learns from them. Every table of a
factored domain (per action: one conditional table per state feature, ``P(f' | parents)``,
and one observation table ``P(o | parents of s')``) is re-estimated row by row — a row is
one configuration of the table's parents — with the designer's row as a Dirichlet prior:

    fitted row = (k · designer row + counts) / (k + n)

where ``n`` is how much data the row saw and ``k`` the prior strength (``--prior-strength``,
pseudo-counts). A row with fewer than ``min_count`` observations keeps the designer's row.

A transition table the designer wrote once for many actions — under ``defaults.effects``, or
a feature no action mentions (it persists) — is estimated once, from the pooled data of every
action that shares it (tied parameters, :func:`tied_groups`): the model says those actions do
not act on the feature, so nothing that happened while one of them ran is credited to it.
``--untied`` fits each action's copy on its own data.

* **With the true state** (a simulator's bag carries it on its world's ``/WORLD/sim/truth``, e.g.
  ``/pearl/sim/truth``; a ``.jsonl`` episode may list ``states``) the counts are counted.
* **Without it** (a real robot's bag) they are *expected* counts from the forward-backward
  pass over the compiled model (EM over the DBN): E-step with the current tables, M-step
  the formula above, repeated until the log-likelihood stops rising. Each iteration cannot
  lower ``log P(observations) + log Dir(prior)`` (with ``k = 0``: the likelihood itself);
  :attr:`FitResult.history` records it.

Episodes: a bag directory (``/pearl/belief`` gives each closed step's action and
observation as the tracker saw them (a bag recorded before the typed interfaces: ``/pearl/belief_marginals``) — timeouts included; ``/WORLD/sim/truth`` the true
state at the start of each action, :mod:`pearl_pomdp.world_truth`) or a ``.jsonl`` file, one episode per line:
``{"actions": [a_0 …], "observations": [o_1 …], "states": [{feature: value} …]}`` (states
optional; ``len(states) == len(actions) + 1``).
"""
from __future__ import annotations

import copy
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from pearl_pomdp.errors import PearlError

__all__ = ["Episode", "FitResult", "load_episodes", "fit_domain", "simulate_episodes", "fitted_section",
           "write_fitted", "tied_groups", "FITTED_MARKER"]

#: The line that starts the appended ``fitted:`` section of a domain file.
FITTED_MARKER = "# ------------------------------------------------------------- fitted by `pearl fit`"


@dataclass
class Episode:
    """One recorded episode: ``actions[k]`` was taken, ``observations[k]`` closed its step.

    ``states`` (optional): the true state at the start of each action and after the last
    one (``len(actions) + 1`` feature → value mappings).
    """

    actions: List[str]
    observations: List[str]
    states: Optional[List[Dict[str, str]]] = None
    source: str = ""


@dataclass
class RowChange:
    """One fitted row: which table, which parent values, how much data, how far it moved."""

    table: str
    row: str
    n: float
    before: Dict[str, float]
    after: Dict[str, float]

    @property
    def change(self) -> float:
        return max(abs(self.after.get(k, 0.0) - self.before.get(k, 0.0)) for k in set(self.before) | set(self.after))


@dataclass
class FitResult:
    """What :func:`fit_domain` produced.

    Attributes:
        domain: the fitted FactoredDomain (the input is left unchanged).
        rows: every row that was re-estimated (enough data), with before/after.
        kept: ``(table, row, n)`` of rows that saw some data but less than ``min_count``.
        with_truth: counted from true states (else EM).
        history: log-likelihood of the observations after each EM iteration (first = the designer's tables).
        episodes, steps: how much data.
    """

    domain: Any
    rows: List[RowChange] = field(default_factory=list)
    kept: List[Tuple[str, str, float]] = field(default_factory=list)
    with_truth: bool = True
    history: List[float] = field(default_factory=list)
    episodes: int = 0
    steps: int = 0
    tied: bool = False

    def largest_changes(self, top: int) -> List[Dict[str, Any]]:
        """The ``top`` rows that moved most: table, row, data, change, and the row before and after
        (probabilities above 0.005, rounded): what the fitting benches print."""
        rows = sorted(self.rows, key=lambda r: -r.change)[:top]
        return [{"table": r.table, "row": r.row, "n": round(r.n, 1), "change": round(r.change, 3),
                 "before": {k: round(v, 3) for k, v in r.before.items() if v > 0.005},
                 "after": {k: round(v, 3) for k, v in r.after.items() if v > 0.005}} for r in rows]

    def tables(self) -> Dict[str, Dict[str, Any]]:
        """Per table: rows fitted, data, largest change (the summary ``pearl fit`` prints)."""
        out: Dict[str, Dict[str, Any]] = {}
        for r in self.rows:
            t = out.setdefault(r.table, {"rows_fitted": 0, "n": 0.0, "max_change": 0.0, "rows_kept": 0})
            t["rows_fitted"] += 1
            t["n"] += r.n
            t["max_change"] = max(t["max_change"], r.change)
        for table, _row, n in self.kept:
            t = out.setdefault(table, {"rows_fitted": 0, "n": 0.0, "max_change": 0.0, "rows_kept": 0})
            t["rows_kept"] += 1
            t["n"] += n
        return out


# ------------------------------------------------------------------ episodes
def episodes_from_bag(path: Union[str, Path], truth: bool = True) -> Episode:
    """The episode of a bag: steps from ``/pearl/belief`` (``pearl_interfaces/msg/Belief``; a bag
    recorded before the typed interfaces: its ``/pearl/belief_marginals`` JSON), the true states from
    the world's truth topic ``/WORLD/sim/truth`` if one was recorded (``pearl_interfaces/msg/WorldTruth``,
    or the JSON of a bag recorded before it: :mod:`pearl_pomdp.world_truth`).

    With ``truth`` false the truth topic is not read (``states`` is ``None``: the fit runs EM).
    A bag cut after its last action began (no state after it) loses that last step. The states are
    counted against the steps, never dropped in silence: a truth topic that does not cover the steps is an
    error.

    Raises:
        PearlError: the bag has no steps, several truth topics, fewer true states than steps, or a
            message that does not decode (names the bag, the topic and what is wrong).
    """
    from pearl_pomdp.bags.reader import BagReader, cdr_string
    from pearl_pomdp.world_truth import truth_records, truth_topics

    reader = BagReader(path)
    info = reader.topics.get("/pearl/belief")
    if info is not None and info.type == "pearl_interfaces/msg/Belief":
        # Decoded from the bag's own message definition (mcap-ros2-support): no ROS import in the core.
        belief = reader.decoder("/pearl/belief")

        def decode(data: bytes) -> dict:
            msg = belief(data)
            return {"step": int(msg.step), "action": msg.action or None, "observation": msg.observation or None}

        topic = "/pearl/belief"
    elif "/pearl/belief_marginals" in reader.topics:
        topic, decode = "/pearl/belief_marginals", lambda data: json.loads(cdr_string(data))  # noqa: E731
    else:
        raise PearlError(f"{path}: no /pearl/belief topic of type pearl_interfaces/msg/Belief: record it (pearl demo "
                         "and `pearl record` with the default topics do) so the fit knows each step's action and "
                         "observation")
    steps = []
    for m in reader.read_messages([topic]):
        body = decode(m.data)
        if body.get("action") is not None:
            steps.append((int(body["step"]), body["action"], body["observation"]))
    steps.sort()
    actions = [a for _, a, _ in steps]
    observations = [o for _, _, o in steps]
    states = None
    worlds = truth_topics(reader)
    if len(worlds) > 1:
        raise PearlError(f"{path}: {len(worlds)} truth topics ({', '.join(worlds)}): a bag of one episode has "
                         "one world's truth")
    if worlds and truth:
        starts = [t["state"] for t in truth_records(reader, worlds[0]) if t.get("phase") == "start"]
        if len(starts) == len(actions) and actions:
            # Cut after the last action began (a run stopped before the world's last state): that
            # action's successor is unknown, so its step is not counted; every other step is.
            actions, observations = actions[:-1], observations[:-1]
        if len(starts) < len(actions) + 1:
            raise PearlError(f"{path}: {worlds[0]} holds {len(starts)} true state(s) at the start of an action for "
                             f"{len(actions)} step(s) on {topic} (the fit needs one before each action and one after "
                             "the last): the world and the manager disagree on the steps, or the truth was recorded "
                             "late; record again, or fit without the truth (pearl fit --no-truth: EM)")
        states = starts[:len(actions) + 1]
    return Episode(actions, observations, states, str(path))


def load_episodes(paths: Sequence[Union[str, Path]], truth: bool = True) -> List[Episode]:
    """Episodes from bag directories and ``.jsonl`` files (see the module doc); with ``truth`` false
    their true states are left out (the fit runs EM).

    Raises:
        PearlError: a file that is neither, or an episode with mismatched lengths (names file and line).
    """
    out: List[Episode] = []
    for raw in paths:
        p = Path(raw)
        if p.suffix == ".jsonl":
            for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), start=1):
                if not line.strip():
                    continue
                try:
                    obj = json.loads(line)
                    ep = Episode(list(obj["actions"]), list(obj["observations"]),
                                 obj.get("states") if truth else None, f"{p}:{i}")
                except (ValueError, KeyError, TypeError) as err:
                    raise PearlError(f"{p}:{i}: not an episode object with actions and observations ({err})") from None
                out.append(ep)
        elif p.is_dir() or p.suffix == ".mcap":
            out.append(episodes_from_bag(p, truth=truth))
        elif not p.exists():
            raise PearlError(f"{p}: no such episode file or bag")
        else:
            raise PearlError(f"{p}: expected a bag directory, an .mcap file or a .jsonl episode file")
    for ep in out:
        if len(ep.observations) != len(ep.actions):
            raise PearlError(f"{ep.source}: {len(ep.actions)} actions but {len(ep.observations)} observations")
        if ep.states is not None and len(ep.states) != len(ep.actions) + 1:
            raise PearlError(f"{ep.source}: {len(ep.states)} states for {len(ep.actions)} actions "
                             f"(need one per action and one after the last)")
    return out


def simulate_episodes(domain, episodes: int, steps: int, seed: int = 0,
                      actions: Optional[Sequence[str]] = None) -> List[Episode]:
    """Episodes sampled from ``domain``'s own model, actions uniformly at random (from
    ``actions`` when given), with the true states: test data for :func:`fit_domain`."""
    model = domain.compile()
    rng = np.random.default_rng(seed)
    names = list(actions) if actions is not None else list(model.actions)
    index = {a: i for i, a in enumerate(model.actions)}
    T = [t.toarray() if hasattr(t, "toarray") else np.asarray(t) for t in model.T]
    out = []
    for e in range(episodes):
        s = int(rng.choice(model.num_states, p=model.b0))
        ep = Episode([], [], [domain.state_assignment(s)], f"simulated:{e}")
        for _ in range(steps):
            a = names[int(rng.integers(len(names)))]
            s = int(rng.choice(model.num_states, p=T[index[a]][s]))
            o = int(rng.choice(model.num_observations, p=model.O[index[a], s]))
            ep.actions.append(a)
            ep.observations.append(model.observations[o])
            assert ep.states is not None
            ep.states.append(domain.state_assignment(s))
        out.append(ep)
    return out


# ------------------------------------------------------------------ counting
def _check_names(domain, episodes: Sequence[Episode]) -> None:
    acts, obs = set(domain.actions), set(domain.observations)
    for ep in episodes:
        for k, (a, o) in enumerate(zip(ep.actions, ep.observations)):
            if a not in acts:
                raise PearlError(f"{ep.source}: step {k + 1}: action {a!r} is not an action of domain {domain.name!r} "
                                 "(is this the domain the episode was recorded with?)")
            if o not in obs:
                raise PearlError(f"{ep.source}: step {k + 1}: observation {o!r} is not a symbol of domain "
                                 f"{domain.name!r}")


def _empty_counts(domain):
    trans = [[np.zeros_like(cpt.table) for cpt in row] for row in domain._transitions]
    obs = [np.zeros_like(cpt.table) for cpt in domain._observations]
    return trans, obs


def _count_truth(domain, episodes):
    trans, obs = _empty_counts(domain)
    sv = domain.state_values
    z_index = {z: i for i, z in enumerate(domain.observations)}
    for ep in episodes:
        idx = [domain.state_index(s) for s in ep.states]
        for k, a_name in enumerate(ep.actions):
            a = domain.actions.index(a_name)
            s, s2 = sv[idx[k]], sv[idx[k + 1]]
            for f, cpt in enumerate(domain._transitions[a]):
                trans[a][f][tuple(s[p] for p in cpt.parents) + (s2[f],)] += 1.0
            ocpt = domain._observations[a]
            obs[a][tuple(s2[p] for p in ocpt.parents) + (z_index[ep.observations[k]],)] += 1.0
    return trans, obs


def _expected_counts(domain, episodes):
    """E-step: expected counts from forward-backward over the compiled model, and log P(observations)."""
    model = domain.compile()
    trans, obs = _empty_counts(domain)
    sv = domain.state_values
    z_index = {z: i for i, z in enumerate(domain.observations)}
    T = [t.tocsr() if hasattr(t, "tocsr") else None for t in model.T]
    import scipy.sparse as sp

    T = [t if t is not None else sp.csr_matrix(np.asarray(model.T[a])) for a, t in enumerate(T)]
    loglik = 0.0
    for ep in episodes:
        acts = [domain.actions.index(a) for a in ep.actions]
        zs = [z_index[o] for o in ep.observations]
        n = len(acts)
        alphas = np.zeros((n + 1, model.num_states))
        alphas[0] = model.b0
        for k in range(n):
            pred = T[acts[k]].T @ alphas[k]
            un = pred * model.O[acts[k], :, zs[k]]
            c = un.sum()
            if c <= 0:
                raise PearlError(f"{ep.source}: step {k + 1}: observation {ep.observations[k]!r} after "
                                 f"{ep.actions[k]!r} is impossible under the current tables (a structural zero): "
                                 "give the designer's table a small probability there, or use episodes with truth")
            loglik += math.log(c)
            alphas[k + 1] = un / c
        beta = np.ones(model.num_states)
        for k in range(n - 1, -1, -1):
            a, z = acts[k], zs[k]
            w = model.O[a, :, z] * beta                      # [S'] likelihood of the future from s'
            xi = T[a].multiply(alphas[k][:, None]).multiply(w[None, :]).tocoo()
            total = xi.sum()
            if total > 0:
                vals = xi.data / total
                s_rows, s2_cols = sv[xi.row], sv[xi.col]
                for f, cpt in enumerate(domain._transitions[a]):
                    key = tuple(s_rows[:, p] for p in cpt.parents) + (s2_cols[:, f],)
                    np.add.at(trans[a][f], key, vals)
                gamma = alphas[k + 1] * beta
                gamma /= gamma.sum()
                ocpt = domain._observations[a]
                np.add.at(obs[a], tuple(sv[:, p] for p in ocpt.parents) + (np.full(len(gamma), z),), gamma)
            beta = T[a] @ w
            beta /= max(beta.max(), 1e-300)                  # scale: only ratios matter
    return trans, obs, loglik


def tied_groups(domain) -> List[Tuple[int, List[int]]]:
    """``(feature, actions)`` for every transition table the designer wrote once for several actions.

    A table under ``defaults.effects`` (or a feature nothing mentions, which persists) is one
    table in the designer's model, shared by every action that does not write its own: those
    actions are declared not to act on the feature. Fitting them separately lets an action be
    credited with what merely happened while it ran — in Pearl, the questions that arise in
    her room while the robot drives there made ``GotoPatientRoom`` look as if it made her
    curious (21 % of drives against 1 % designed, issue 21). Tied, their counts are pooled
    and one row is estimated for all of them, as the model declares.
    """
    groups: List[Tuple[int, List[int]]] = []
    for f in range(len(domain.features)):
        by_origin: Dict[str, List[int]] = {}
        for a in range(len(domain.actions)):
            origin = getattr(domain._transitions[a][f], "origin", "")
            if origin and not origin.startswith("actions."):
                by_origin.setdefault(origin, []).append(a)
        groups.extend((f, acts) for acts in by_origin.values() if len(acts) > 1)
    return groups


def _tie(domain, trans_counts) -> None:
    """Pool the counts of each :func:`tied_groups` group, in place (every member gets the sum)."""
    for f, acts in tied_groups(domain):
        shapes = {trans_counts[a][f].shape for a in acts}
        if len(shapes) != 1:   # cannot happen for one spec; a hand-built domain may differ: leave it untied
            continue
        total = sum(trans_counts[a][f] for a in acts)
        for a in acts:
            trans_counts[a][f] = total.copy()


# ------------------------------------------------------------------ the M-step
def _row_name(domain, parents: Tuple[int, ...], combo: Tuple[int, ...]) -> str:
    return ",".join(domain.features[p].values[v] for p, v in zip(parents, combo)) if parents else "*"


def _update(domain, trans_counts, obs_counts, prior_strength: float, min_count: float, prior):
    """New FactoredDomain with every row that saw ≥ min_count data re-estimated against ``prior``'s rows."""
    new = copy.copy(domain)
    new._transitions = [[copy.copy(c) for c in row] for row in domain._transitions]
    new._observations = [copy.copy(c) for c in domain._observations]
    new._compiled = None
    rows: List[RowChange] = []
    kept: List[Tuple[str, str, float]] = []

    def fit_table(cpt, prior_cpt, counts, name: str, child_names: Sequence[str]):
        table = np.array(prior_cpt.table, dtype=float)
        n_rows = counts.sum(axis=-1)
        for combo in zip(*np.nonzero(n_rows > 0)) if counts.ndim > 1 else ([()] if n_rows > 0 else []):
            combo = tuple(int(c) for c in combo)
            n = float(n_rows[combo])
            row_name = _row_name(domain, cpt.parents, combo)
            if n < min_count:
                kept.append((name, row_name, n))
                continue
            prior_row = np.asarray(prior_cpt.table[combo], dtype=float)
            fitted = (prior_strength * prior_row + counts[combo]) / (prior_strength + n)
            table[combo] = fitted
            rows.append(RowChange(name, row_name, n,
                                  {c: float(p) for c, p in zip(child_names, prior_row) if p > 0},
                                  {c: float(p) for c, p in zip(child_names, fitted) if p > 1e-12}))
        out = copy.copy(cpt)
        out.table = table
        return out

    for a, action in enumerate(domain.actions):
        for f, feat in enumerate(domain.features):
            new._transitions[a][f] = fit_table(domain._transitions[a][f], prior._transitions[a][f],
                                               trans_counts[a][f], f"transition {action}/{feat.name}", feat.values)
        new._observations[a] = fit_table(domain._observations[a], prior._observations[a], obs_counts[a],
                                         f"observation {action}", domain.observations)
    return new, rows, kept


def fit_domain(domain, episodes: Sequence[Episode], prior_strength: float = 10.0, min_count: float = 5.0,
               em_iterations: int = 30, tolerance: float = 1e-4, use_truth: Optional[bool] = None,
               tied: bool = True) -> FitResult:
    """Fit ``domain``'s tables to ``episodes`` (see the module doc).

    Args:
        tied: estimate a transition table the designer wrote once (``defaults.effects``, or
            persistence) once for all the actions that share it (:func:`tied_groups`);
            ``False`` fits every action's copy on its own data.
        prior_strength: ``k``, pseudo-counts of the designer's row (≥ 0).
        min_count: rows with less data keep the designer's row (> 0).
        em_iterations, tolerance: EM stops after this many iterations, or when the
            log-likelihood rises by less than ``tolerance``.
        use_truth: count from true states (default: when every episode has them).

    Raises:
        PearlError: no episodes, names that are not in the domain, bad settings.
    """
    if not episodes:
        raise PearlError("no episodes to fit")
    if prior_strength < 0 or not math.isfinite(prior_strength):
        raise PearlError(f"--prior-strength must be >= 0, got {prior_strength}")
    if min_count <= 0:
        raise PearlError(f"min_count must be > 0, got {min_count}")
    _check_names(domain, episodes)
    truth = all(ep.states is not None for ep in episodes) if use_truth is None else use_truth
    if truth and any(ep.states is None for ep in episodes):
        raise PearlError("use_truth: some episodes carry no true states")
    steps = sum(len(ep.actions) for ep in episodes)
    if truth:
        trans, obs = _count_truth(domain, episodes)
        if tied:
            _tie(domain, trans)
        fitted, rows, kept = _update(domain, trans, obs, prior_strength, min_count, domain)
        return FitResult(fitted, rows, kept, True, [], len(episodes), steps, tied)
    current = domain
    history: List[float] = []
    rows, kept = [], []
    for _ in range(max(1, em_iterations)):
        trans, obs, loglik = _expected_counts(current, episodes)
        if tied:
            _tie(domain, trans)
        history.append(loglik)
        if len(history) > 1 and history[-1] - history[-2] < tolerance:
            break
        current, rows, kept = _update(current, trans, obs, prior_strength, min_count, domain)
    # The rows' "before" is the designer's table: _update compares against `domain` (the prior).
    return FitResult(current, rows, kept, False, history, len(episodes), steps, tied)


# ------------------------------------------------------------------ writing
def _fmt(dist: Dict[str, float], digits: int = 6) -> str:
    """A row as YAML flow; ``digits`` significant digits. The fitted rows are written with 12,
    so that they still sum to 1 within the loader's tolerance after rounding (with 6, a row of
    eight small entries summed to 0.999999 and the fitted file did not load)."""
    return "{" + ", ".join(f"{json.dumps(k)}: {p:.{digits}g}" for k, p in dist.items()) + "}"


def fitted_section(result: FitResult, prior_strength: float) -> str:
    """The ``fitted:`` YAML section for ``result`` (appended to the domain file by :func:`write_fitted`)."""
    lines = [FITTED_MARKER,
             f"# {len(result.rows)} rows re-estimated from {result.episodes} episode(s), {result.steps} steps "
             f"({'counted from the true states' if result.with_truth else 'EM without the true state'}); "
             f"prior: the designer's rows above, strength {prior_strength:g}. Rows with less data keep them.",
             "fitted:"]
    by_kind: Dict[str, Dict[str, Dict[str, List[RowChange]]]] = {"transitions": {}, "observations": {}}
    for r in result.rows:
        kind, rest = r.table.split(" ", 1)
        if kind == "transition":
            action, feature = rest.split("/")
            by_kind["transitions"].setdefault(action, {}).setdefault(feature, []).append(r)
        else:
            by_kind["observations"].setdefault(rest, {}).setdefault("", []).append(r)
    # (action, feature) -> how many actions share its table, and where the designer wrote it
    shared: Dict[Tuple[str, str], Tuple[int, str]] = {}
    if result.tied:
        d = result.domain
        for f, acts in tied_groups(d):
            origin = d._transitions[acts[0]][f].origin
            for a in acts:
                shared[(d.actions[a], d.features[f].name)] = (len(acts), origin)
    for kind in ("transitions", "observations"):
        if not by_kind[kind]:
            continue
        lines.append(f"  {kind}:")
        for action, tables in by_kind[kind].items():
            lines.append(f"    {action}:")
            for feature, rs in tables.items():
                indent = "      "
                if kind == "transitions":
                    lines.append(f"      {feature}:")
                    indent = "        "
                tie = shared.get((action, feature)) if kind == "transitions" else None
                pooled = f" pooled over the {tie[0]} actions of {tie[1]}," if tie else ""
                for r in rs:
                    lines.append(f"{indent}{json.dumps(r.row)}: {_fmt(r.after, 12)}   "
                                 f"# fitted: n={r.n:.4g},{pooled} was {_fmt(r.before)}")
    return "\n".join(lines) + "\n"


def write_fitted(domain_path: Union[str, Path], result: FitResult, out: Union[str, Path],
                 prior_strength: float) -> Path:
    """Write the domain file unchanged (the designer's text and comments) plus the ``fitted:`` section.

    A ``fitted:`` section already in the file (from an earlier fit) is replaced.
    """
    text = Path(domain_path).read_text(encoding="utf-8")
    if FITTED_MARKER in text:
        text = text[:text.index(FITTED_MARKER)]
    if not text.endswith("\n"):
        text += "\n"
    from pearl_pomdp.atomic import atomic_write

    body = text + "\n" + fitted_section(result, prior_strength)
    out = Path(out)
    atomic_write(out, body.encode("utf-8"))
    return out
