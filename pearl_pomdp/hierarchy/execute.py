"""EXECUTE: the hierarchical policy, polled top-down at every step (Pineau & Thrun, Table 1).

``EXECUTE(h, b)``: ``a = π_h(b)``; if ``a`` is primitive return it, else
``EXECUTE(h_a, b)``. The full trace root → … → primitive is repeated at *every* time
step (polling, as in Dietterich's MAXQ): terminal states of a subtask are not
observable, so a subtask is never "run to termination".

Each subtask's local policy is a set of α-vectors over its abstract model's states
(:mod:`pearl_pomdp.hierarchy.abstraction`). The full belief ``b [S]`` projects onto a
subtask by its X+ marginal, ``b_h = P_hᵀ b``, so ``α·b_h = (P_h α)·b``: the vectors are
stored *expanded* to the full state space once (``alphas_full [K, S]``) and a decision
is a few ``K×S`` mat-vecs.

A subtask with ``lookahead: d`` (hierarchy spec) decides by exact forward search instead
(:class:`~pearl_pomdp.policies.lookahead.Lookahead`): its abstract model and horizon-``h`` vectors are kept, and the
action is the argmax of the exact horizon-``h + d`` Q-values at the current belief.

The subtask policies are :mod:`pearl_pomdp.hierarchy.subtask`'s; saving and loading is
:mod:`pearl_pomdp.hierarchy.storage`'s directory format.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Callable, Collection, Dict, FrozenSet, List, Optional, Sequence, Tuple, Union, cast

import numpy as np

from pearl_pomdp.errors import PolicyError
from pearl_pomdp.hierarchy.storage import read_policy_dir, write_policy_dir
from pearl_pomdp.hierarchy.subtask import SubtaskPolicy
from pearl_pomdp.interfaces import Decision, TraceStep, forbidden_indices
from pearl_pomdp.model.factored import FactoredDomain
from pearl_pomdp.policies.lookahead import Lookahead

__all__ = ["HierarchicalPolicy", "load_hierarchical_policy"]


#: A subtask's runner-up offer sits in EXECUTE's memo under its name plus this (no name has a NUL).
RUNNER_UP = "\0runner-up"


class HierarchicalPolicy:
    """The collection of local policies, with EXECUTE.

    Args:
        root: the top subtask.
        subtasks: subtask name → :class:`SubtaskPolicy`.
        action_names: the full model's primitive action names (``Decision.action`` indexes them).
        fingerprint: the full model's :meth:`~pearl_pomdp.model.pomdp.Pomdp.fingerprint`.
        report: the PLAN report (``pearl plan --json``'s object).
    """

    def __init__(self, root: str, subtasks: Dict[str, SubtaskPolicy], action_names: List[str],
                 fingerprint: str = "", report: Optional[dict] = None, hierarchy_name: str = "",
                 model_name: str = ""):
        self.root = root
        self.subtasks = subtasks
        self.action_names = list(action_names)
        self.fingerprint = fingerprint
        self.report = report or {}
        #: The abstract models PLAN solved, per subtask (kept for inspection; not saved).
        self.abstract_models: Dict[str, Any] = {}
        self.hierarchy_name = hierarchy_name
        self.model_name = model_name
        self._index = {name: i for i, name in enumerate(self.action_names)}
        self.num_states = int(next(iter(subtasks.values())).state_to_model.shape[0])
        #: The root plans online over its children (``solver: online``): :meth:`bind_model` builds the search.
        self.online = subtasks[root].online is not None
        self.online_root: Any = None
        #: Policy-contingent (every subtask solved as in :mod:`pearl_pomdp.hierarchy.plan`'s
        #: default) or the paper's eq. 15–17 corner parameterisation.
        self.contingent = bool(subtasks[root].contingent) or self.online
        if self.contingent:
            # Per subtask: full primitive index -> its model's action index (-1: not below it).
            self._to_model = {}
            for name, sub in subtasks.items():
                if sub.model_actions is None:
                    continue   # the online root: no model of its own
                table = np.full(len(self.action_names), -1, dtype=np.int64)
                for a, act in enumerate(cast(List[str], sub.model_actions)):
                    if act in self._index:
                        table[self._index[act]] = a
                self._to_model[name] = table
        #: Beliefs the last :meth:`execute` expanded in its forward search (0: one step, no search).
        self.last_expansions = 0
        self._pick_cache: Dict[tuple, tuple] = {}
        #: The runner-up of each cached pick (same keys), for the trace.
        self._rival_cache: Dict[tuple, Optional[tuple]] = {}
        #: Subtasks with a subtask among their children: their children's offers go up to their
        #: parent (:meth:`offers`), so a level of organisation hides no alternative.
        self._groups = {name for name, sub in subtasks.items() if any(sub.abstract)}
        #: Per subtask, the full-model indices of the primitives below it (what a veto can leave).
        self._below: Dict[str, FrozenSet[int]] = {}
        for name in subtasks:
            self._primitives_below(name)
        #: The execute mode, a strategy chosen once: ``(belief, banned primitive indices) -> Decision``.
        self._mode: Callable[[np.ndarray, FrozenSet[int]], Decision] = (
            self._execute_online if self.online else self._execute_contingent if self.contingent
            else self._execute_corners)

    def bind_model(self, model, bounds=None) -> None:
        """Give an online root (``solver: online``) the full model its search steps (PLAN and
        :func:`load_hierarchical_policy` call this); nothing to do for an offline root.

        Args:
            model: the full :class:`~pearl_pomdp.model.pomdp.Pomdp` the policy was planned for.
            bounds: the search's bounds (default: :func:`~pearl_pomdp.online.decider.default_bounds`).
        """
        if not self.online:
            return
        from pearl_pomdp.hierarchy.online_root import OnlineRoot, online_settings

        record = cast(dict, self.subtasks[self.root].online)
        self.online_root = OnlineRoot(self, model, online_settings(record), seed=int(record.get("seed", 0)),
                                      bounds=bounds)

    def action_index(self, name: str) -> int:
        """The full model's index of primitive ``name``."""
        return self._index[name]

    def is_group(self, name: str) -> bool:
        """Whether subtask ``name`` has subtasks among its children (it passes their offers up)."""
        return name in self._groups

    def _primitives_below(self, name: str) -> FrozenSet[int]:
        got = self._below.get(name)
        if got is None:
            self._below[name] = frozenset()   # a cycle (rejected at load) ends here
            sub = self.subtasks[name]
            got = frozenset().union(*[self._primitives_below(c) if sub.abstract[k] else {self._index[c]}
                                      for k, c in enumerate(sub.actions)])
            self._below[name] = got
        return got

    # ------------------------------------------------------------- EXECUTE
    def execute(self, belief) -> Decision:
        """EXECUTE(root, b): walk the hierarchy top-down and return the primitive action
        (:meth:`execute_without` with nothing forbidden).

        Args:
            belief: the full belief ``[S]`` (a distribution over the full model's states).

        Returns:
            :class:`Decision` with the trace root → … → primitive and each subtask's value.
        """
        return self.execute_without(belief, ())

    def execute_without(self, belief, forbidden: Collection[str]) -> Decision:
        """EXECUTE with the primitives in ``forbidden`` (names) masked for this one decision.

        Every subtask chooses among its children that are still possible: a primitive not
        forbidden, a subtask with a primitive left below it. Policy-contingent: each child offers
        the best primitive it has left, and the subtask takes the offer with the largest one-step
        value over its own model (a deeper root search masks the first step only: later steps
        may take the action again). Otherwise: the largest Q-value (lookahead) or vector among
        the children left. The trace's runner-ups are among the children left too.

        Raises:
            PolicyError: a name is not a primitive action, every action is forbidden, or a
                subtask has no value for any child left (no vector carries one).
        """
        banned = forbidden_indices(self.action_names, forbidden) if forbidden else frozenset()
        b = np.asarray(belief, dtype=float)
        if b.shape != (self.num_states,):
            raise ValueError(f"belief has shape {b.shape}, expected ({self.num_states},)")
        return self._mode(b, banned)

    def _execute_online(self, b: np.ndarray, banned: FrozenSet[int]) -> Decision:
        """The online root's mode: its search over the children's picks (:mod:`pearl_pomdp.hierarchy.online_root`)."""
        if self.online_root is None:
            raise PolicyError(f"the root {self.root!r} plans online and needs the model: load the policy with "
                              f"load_hierarchical_policy(directory, domain) (or call bind_model)")
        return self.online_root.execute(b, banned)

    def _execute_corners(self, b: np.ndarray, banned: FrozenSet[int]) -> Decision:
        """The mode of the paper's eq. 15–17 parameterisation: each subtask on the trace takes its
        largest Q-value (lookahead) or vector among its children still possible."""
        trace = []
        node = self.root
        for _ in range(len(self.subtasks) + 1):
            sub = self.subtasks[node]
            allowed = np.array([bool(self._below[c] - banned) if sub.abstract[k] else self._index[c] not in banned
                                for k, c in enumerate(sub.actions)])
            got = sub.choose(b, allowed)
            if got is None:
                raise PolicyError(f"subtask {node!r} has no value for any action left once "
                                  f"{', '.join(sorted(self.action_names[i] for i in banned))} is forbidden")
            k, value = got
            choice = sub.actions[k]
            trace.append(TraceStep(node, choice, value, *sub.runner_up(b, k, allowed)))
            if not sub.abstract[k]:
                return Decision(self._index[choice], choice, trace)
            node = choice
        raise PolicyError(f"the hierarchy below {self.root!r} has a cycle")  # pragma: no cover - validated at load

    #: Picks remembered per (subtask, model marginal); the cache is emptied when it is full.
    PICK_CACHE = 4096

    # ------------------------------------------------- policy-contingent EXECUTE
    def offers(self, children: Sequence[str], b: np.ndarray, memo: Dict[str, Any],
               banned: FrozenSet[int] = frozenset()) -> List[Tuple[int, Tuple[int, ...]]]:
        """What a subtask with these ``children`` chooses among at the full belief ``b``:
        ``(primitive index, path)`` pairs, ``path`` the child indices from that subtask down.

        A primitive child offers itself. A child subtask whose children are all primitives
        offers the primitive its own policy picks (:meth:`pick`). A child subtask that has
        subtasks among its children (a *group*, such as Pearl's ``Assist``) passes its
        children's offers up instead of choosing among them by its own value: measured on
        Pearl (docs/hierarchy.md, "Groups pass their offers up"), a group ranked by its own
        option value offered ``ConfirmGuideToPhysio`` where the root, which also values what
        follows the group's job, would have answered her question first — and the root, shown
        only the confirmation, waited instead for a dozen steps. ``banned``: primitives no
        child may offer (a veto)."""
        out: List[Tuple[int, Tuple[int, ...]]] = []
        for k, child in enumerate(children):
            if child not in self.subtasks:
                prim = self._index[child]
                if prim not in banned:
                    out.append((prim, (k,)))
            elif child in self._groups:
                grand = self.subtasks[child].actions
                out.extend((prim, (k,) + path) for prim, path in self.offers(grand, b, memo, banned))
            else:
                offer = self.pick(child, b, memo, banned)
                if offer is not None:
                    out.append((offer[0], (k,)))
        return out

    def pick_projected(self, name: str, bh: np.ndarray, banned: FrozenSet[int] = frozenset()) -> Any:
        """:meth:`pick` of a subtask of primitives given its model belief ``bh`` directly (what it decides
        on: the X+ marginal), e.g. the particle belief of an online root's search node. ``None`` when every
        child is banned."""
        if name in self._groups:
            raise PolicyError(f"subtask {name!r} has subtasks among its children: pick it at a full belief")
        key = (name, np.asarray(bh, dtype=float).tobytes())
        got = None if banned else self._pick_cache.get(key)
        if got is not None:
            return got
        sub = self.subtasks[name]
        offers = [(self._index[c], (k,)) for k, c in enumerate(sub.actions) if self._index[c] not in banned]
        best, second = self._rank_offers(name, bh, offers)
        if not banned:
            self._remember(key, best, second)
        return best

    def _rank_offers(self, name: str, bh: np.ndarray,
                     offers: Sequence[Tuple[int, Tuple[int, ...]]]) -> Tuple[Any, Any]:
        """:meth:`_rank` of ``offers`` by subtask ``name``'s one-step values at its model belief ``bh``,
        computed for the offered actions only (the same values:
        :meth:`~pearl_pomdp.policies.lookahead.OneStep.q`)."""
        if not offers:
            return None, None
        table = self._to_model[name]
        one_step = self.subtasks[name].one_step
        wanted = [int(table[prim]) for prim, _ in offers]
        every = len(set(wanted)) == one_step.A   # no mask to build
        return self._rank(one_step.q(bh, None if every else wanted), table, offers)

    @staticmethod
    def _rank(q: np.ndarray, table: np.ndarray, offers: Sequence[Tuple[int, Tuple[int, ...]]]) -> Tuple[Any, Any]:
        """The best of ``offers`` by the one-step value ``q[table[prim]]`` as ``(primitive, child
        index, value, path)`` and the runner-up as ``(primitive, path, value)``, the first on ties
        (``None`` when there is none)."""
        best: Optional[tuple] = None
        second: Optional[tuple] = None
        for prim, path in offers:
            value = float(q[table[prim]])
            if best is None or value > best[2]:
                if best is not None:
                    second = (best[0], best[3], best[2])
                best = (prim, path[0], value, path)
            elif second is None or value > second[2]:
                second = (prim, path, value)
        return best, second

    def _remember(self, key: tuple, best: Optional[tuple], second: Optional[tuple]) -> None:
        """Cache a pick and its runner-up under the same key (emptied together when full); no pick
        (nothing left below) is not cached: a miss values it again, as a cached ``None`` did."""
        if best is None:
            return
        if len(self._pick_cache) >= self.PICK_CACHE:
            self._pick_cache.clear()
            self._rival_cache.clear()
        self._pick_cache[key] = best
        self._rival_cache[key] = second

    def pick(self, name: str, b: np.ndarray, memo: Dict[str, Any], banned: FrozenSet[int] = frozenset()) -> Any:
        """``(primitive index, child index, value, path)`` subtask ``name`` chooses at the full belief ``b``.

        Its children's offers (:meth:`offers`) are valued by one Bellman step over its own
        model, ``Q(b, a) = b·R_a + γ Σ_o V(b T_a diag O_{a,o})`` with ``V`` its α-vectors — the
        value it was planned with, so the parent sees each child as the child acts — and the
        largest is taken (the first offer on ties). ``path``: the child indices from ``name``
        down to the subtask that made the offer. ``memo`` holds the subtasks already asked at
        this belief. ``banned``: full-model primitive indices no child may offer (a veto);
        ``None`` when nothing is left below ``name``."""
        if name in memo:
            return memo[name]
        sub = self.subtasks[name]
        # A subtask's pick depends on the belief only through its own model's marginal (its
        # children's features are among its own): the same marginal, the same pick.
        bh = sub.project(b)[0]
        key = (name, bh.tobytes())
        got = None if banned else self._pick_cache.get(key)
        if got is not None:
            memo[name] = got
            memo[name + RUNNER_UP] = self._rival_cache[key]
            return got
        best, second = self._rank_offers(name, bh, self.offers(sub.actions, b, memo, banned))
        memo[name] = best
        memo[name + RUNNER_UP] = second
        if not banned:   # a masked pick is for this decision only: not cached
            self._remember(key, best, second)
        return best

    def _search_value(self, name: str, b: np.ndarray, depth: int, budget: List[int],
                      banned: FrozenSet[int] = frozenset()) -> Any:
        """:meth:`pick` with ``depth`` steps of forward search over subtask ``name``'s model:
        each offer's successors are valued by the same choice one step shallower (the
        children asked again at every successor), the α-vectors at depth 1. ``budget[0]``
        counts down the beliefs expanded; once it is spent, successors take their vector
        value. Deterministic: offers in child order, observations in index order. ``banned``
        masks this step's offers only (the successors are later steps)."""
        memo: Dict[str, Any] = {}
        if depth <= 1 or budget[0] <= 0:
            return self.pick(name, b, memo, banned)
        sub = self.subtasks[name]
        la = cast(Lookahead, sub.lookahead)
        table = self._to_model[name]
        bh = sub.project(b)[0]
        best: Optional[tuple] = None
        for prim, path in self.offers(sub.actions, b, memo, banned):
            a = int(table[prim])
            predicted = np.asarray(la._Tt[a] @ bh)
            value = float(bh @ la.R[:, a])
            for o in la._live_obs[a]:
                successor = predicted * la.O[a, :, o]
                mass = float(successor.sum())
                if mass <= 1e-300:
                    continue
                if budget[0] > 0:
                    budget[0] -= 1
                    nxt = sub.lift(successor / mass)
                    value += la.discount * mass * self._search_value(name, nxt, depth - 1, budget)[2]
                else:
                    value += la.discount * float((la.alphas @ successor).max())
            if best is None or value > best[2]:
                best = (prim, path[0], value, path)
        return best

    def _execute_contingent(self, b: np.ndarray, banned: FrozenSet[int] = frozenset()) -> Decision:
        root = self.subtasks[self.root]
        budget = [root.expansions]
        memo: Dict[str, Any] = {}
        if root.search_depth > 1:
            got = self._search_value(self.root, b, root.search_depth, budget, banned)
            memo = {}   # the search asked the children at other beliefs too
        else:
            got = self.pick(self.root, b, memo, banned)
        if got is None:
            raise PolicyError(f"no action is left below {self.root!r} once {len(banned)} are forbidden")
        prim, k, value, path = got
        self.last_expansions = root.expansions - budget[0] if root.search_depth > 1 else 0
        # A searched root's values are its search's; the runner-up by one step would not compare.
        rival = self._runner_up(self.root, b, memo, prim, path, banned) if root.search_depth <= 1 else ("", math.nan)
        trace = [TraceStep(self.root, root.actions[k], value, *rival)]
        # Down the path to the subtask that offered the primitive: each group on the way with its
        # own value of that primitive (it passed the offer up; it did not choose it).
        node, child = self.root, root.actions[k]
        for idx in path[1:]:
            node = child
            sub = self.subtasks[node]
            child = sub.actions[idx]
            model_action = int(self._to_model[node][prim])
            trace.append(TraceStep(node, child, float(sub.one_step.q(sub.project(b)[0], [model_action])[model_action])))
        for _ in range(len(self.subtasks) + 1):
            if child not in self.subtasks:
                return Decision(self._index[child], child, trace, expansions=self.last_expansions)
            node = child
            picked, k, value, picked_path = self.pick(node, b, memo, banned)
            child = self.subtasks[node].actions[k]
            trace.append(TraceStep(node, child, value, *self._runner_up(node, b, memo, picked, picked_path, banned)))
        raise PolicyError(f"the hierarchy below {self.root!r} has a cycle")  # pragma: no cover - validated at load

    def _runner_up(self, name: str, b: np.ndarray, memo: Dict[str, Any], chosen: int, chosen_path: Tuple[int, ...],
                   banned: FrozenSet[int] = frozenset()) -> Tuple[str, float]:
        """The best offer subtask ``name`` did not take at ``b``, by the one-step value it chose with:
        ``(label, value)``, the label the children's names down to the primitive (``Rest→GoHome``);
        ``("", NaN)`` when it had no other offer. ``chosen``/``chosen_path``: what it took (its
        :meth:`pick`, which kept the runner-up in ``memo``, or else the offers are valued again)."""
        best: Optional[Tuple[int, Tuple[int, ...], float]]
        picked = memo.get(name)
        if picked is not None and picked[0] == chosen and picked[3] == chosen_path and name + RUNNER_UP in memo:
            best = memo[name + RUNNER_UP]
        else:
            sub = self.subtasks[name]
            others = [o for o in self.offers(sub.actions, b, memo, banned) if o != (chosen, chosen_path)]
            got = self._rank_offers(name, sub.project(b)[0], others)[0]
            best = None if got is None else (got[0], got[3], got[2])
        if best is None:
            return "", math.nan
        prim, path, value = best
        names, node = [], name
        for idx in path:
            child = self.subtasks[node].actions[idx]
            names.append(child)
            node = child
        if names[-1] != self.action_names[prim]:
            names.append(self.action_names[prim])
        return "→".join(names), value

    def _pick_batch(self, name: str, B: np.ndarray, memo: Dict[str, np.ndarray]) -> np.ndarray:
        """:meth:`pick`'s primitive for every row of ``B`` ``[N, S]`` at once (ties as :meth:`pick`)."""
        got = memo.get(name)
        if got is not None:
            return got
        sub = self.subtasks[name]
        Q = sub.one_step.q_rows(sub.project(B))
        table = self._to_model[name]
        offers = np.stack(self._offer_columns(sub.actions, B, memo), axis=1)          # [N, J]
        values = np.take_along_axis(Q, table[offers], axis=1)
        memo[name] = offers[np.arange(B.shape[0]), np.argmax(values, axis=1)]
        return memo[name]

    def corner_picks(self, name: str) -> np.ndarray:
        """``[S]`` int64: the primitive subtask ``name`` picks at the belief certain of each state (``π_h(s)``).

        A subtask of primitives decides on its own model's marginal alone, and a certain belief
        projects onto one model state: one pick per model state is enough (the ward's 233,280
        corners cost 180 one-step searches, not 233,280 dense rows). A group asks its children at
        every corner, 256 corners at a time."""
        sub = self.subtasks[name]
        S = self.num_states
        if name in self._groups:
            return np.concatenate([self._pick_batch(name, np.eye(S)[lo:lo + 256], {})
                                   for lo in range(0, S, 256)]).astype(np.int64)
        used = np.unique(sub.state_to_model)
        corners = np.zeros((used.size, sub.alphas.shape[1]))
        corners[np.arange(used.size), used] = 1.0
        Q = sub.one_step.q_rows(corners)
        prims = np.array([self._index[c] for c in sub.actions], dtype=np.int64)
        pick = np.zeros(sub.alphas.shape[1], dtype=np.int64)
        pick[used] = prims[np.argmax(Q[:, self._to_model[name][prims]], axis=1)]
        return pick[sub.state_to_model]

    def _offer_columns(self, children: Sequence[str], B: np.ndarray, memo: Dict[str, np.ndarray]) -> List[np.ndarray]:
        """:meth:`offers` for every row of ``B`` at once: one ``[N]`` column of primitives per offer, in its order."""
        cols: List[np.ndarray] = []
        for child in children:
            if child not in self.subtasks:
                cols.append(np.full(B.shape[0], self._index[child], dtype=np.int64))
            elif child in self._groups:
                cols.extend(self._offer_columns(self.subtasks[child].actions, B, memo))
            else:
                cols.append(self._pick_batch(child, B, memo))
        return cols

    def action(self, belief) -> int:
        """The primitive action index EXECUTE picks at ``belief`` (the flat-policy protocol)."""
        return self.execute(belief).action

    def actions_batch(self, beliefs: np.ndarray) -> np.ndarray:
        """EXECUTE for ``N`` beliefs ``[N, S]`` at once → ``[N]`` primitive indices (used by simulation).

        A policy-contingent root with a deeper search decides belief by belief (the search
        is per belief); otherwise every level is batched."""
        B = np.asarray(beliefs, dtype=float)
        if self.online or (self.contingent and self.subtasks[self.root].search_depth > 1):
            return np.array([self.execute(b).action for b in np.atleast_2d(B)], dtype=np.int64)
        if self.contingent:
            return self._pick_batch(self.root, np.atleast_2d(B), {})
        out = np.full(B.shape[0], -1, dtype=np.int64)
        pending = [(self.root, np.arange(B.shape[0]))]
        while pending:
            node, rows = pending.pop()
            sub = self.subtasks[node]
            k = sub.choose_batch(B[rows])
            for j in np.unique(k):
                chosen = rows[k == j]
                name = sub.actions[j]
                if sub.abstract[j]:
                    pending.append((name, chosen))
                else:
                    out[chosen] = self._index[name]
        return out

    def values(self, belief) -> Dict[str, float]:
        """Every subtask's value at ``belief`` (not only those on the trace)."""
        b = np.asarray(belief, dtype=float)
        if self.contingent:   # an online root is too; its value is its search's
            memo: Dict[str, tuple] = {}
            out = {name: self.pick(name, b, memo)[2] for name in self.subtasks if not (self.online and name == self.root)}
            return {self.root: self.execute(b).trace[0].value, **out} if self.online else out
        return {name: sub.value(b) for name, sub in self.subtasks.items()}

    def save(self, directory: Union[str, Path]) -> Path:
        """Write ``policy.npz`` + ``hierarchy.json`` into ``directory`` (created), atomically per file
        (:func:`~pearl_pomdp.hierarchy.storage.write_policy_dir`).

        Returns:
            The directory.
        """
        return write_policy_dir(directory, self)


def load_hierarchical_policy(directory: Union[str, Path], domain) -> HierarchicalPolicy:
    """Load a policy saved by :meth:`HierarchicalPolicy.save` and check it belongs to ``domain``.

    Args:
        directory: the policy directory (``pearl plan --out DIR``).
        domain: the FactoredDomain (compiled here) or flat Pomdp the policy must match.

    Raises:
        PolicyError: missing/corrupt files, a checksum mismatch, or a model-fingerprint
            mismatch (the message names the file and what differs).
    """
    model = domain.compile() if isinstance(domain, FactoredDomain) else domain
    header, subtasks = read_policy_dir(directory, model)
    policy = HierarchicalPolicy(header["root"], subtasks, list(model.actions), model.fingerprint(), header.get("report"),
                                header.get("hierarchy", ""), header.get("model_name", ""))
    policy.bind_model(model)   # an online root's search steps the model (nothing for an offline root)
    return policy
