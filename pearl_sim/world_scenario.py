"""Scenario files of the reception and the ward: what their loaders share.

Both worlds' files have the same frame — ``world:``, shared top-level fields, ``episodes:`` of
overrides merged key by key, a ``map`` of named places, ``seed`` and ``max_steps`` — and the same
checks, each error naming the file and the field path. The people in them (visitors, residents)
and each world's fields and ranges stay in ``pearl_sim/reception/scenario.py`` and
``pearl_sim/ward/scenario.py``. (The nursing home's ``pearl_sim/nursing_home/scenario.py`` has its own format.)
"""
from __future__ import annotations

import copy
from pathlib import Path
from typing import Any, Callable, Dict, List, Mapping, Sequence, Tuple, TypeVar, Union

from pearl_pomdp.errors import SpecError

__all__ = ["PlacesAndTimeout", "Checker", "merge", "read_map", "read_seed_and_steps", "load_episodes"]

S = TypeVar("S")


class PlacesAndTimeout:
    """What a scenario with a ``map`` of named places and a ``step_timeout`` answers (a dataclass's base)."""

    map: Dict[str, Tuple[float, float]]
    step_timeout: float

    def distance(self, a: str, b: str) -> float:
        """Straight-line distance in metres between two named places."""
        (xa, ya), (xb, yb) = self.map[a], self.map[b]
        return float(((xa - xb) ** 2 + (ya - yb) ** 2) ** 0.5)

    def tracker_parameters(self) -> Dict[str, Any]:
        """The belief tracker's parameters this scenario sets: its step timeout."""
        return {"step_timeout": float(self.step_timeout)}


def merge(base: dict, over: dict) -> dict:
    """``base`` with ``over`` on top: mappings merged key by key, anything else replaced (both copied)."""
    out = copy.deepcopy(base)
    for k, v in over.items():
        out[k] = merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else copy.deepcopy(v)
    return out


class Checker:
    """The checks of one scenario file; every error is a ``SpecError`` naming ``source`` and the field path."""

    def __init__(self, source: str):
        self.source = source

    def fail(self, where: str, problem: str) -> SpecError:
        """The error for the field ``where`` (to raise)."""
        return SpecError(self.source, where, problem)

    def number(self, node: dict, key: str, where: str, default: float, low: float, high: float, unit: str = "") -> float:
        """``node[key]`` (``default`` when absent), a number in [low, high]; ``where`` is the path prefix."""
        value = node.get(key, default)
        return self.value(value, f"{where}{key}", low, high, unit)

    def value(self, value: Any, where: str, low: float, high: float, unit: str = "") -> float:
        """``value``, a number in [low, high] (``unit`` named in the error), as a float."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(where, f"{value!r} is not a number")
        if not low <= float(value) <= high:
            raise self.fail(where, f"{value}{(' ' + unit) if unit else ''} is outside [{low:g}, {high:g}]")
        return float(value)

    def mapping(self, node: Any, where: str, keys: Tuple[str, ...]) -> dict:
        """``node``, a mapping with no key but ``keys`` (``None``: an empty one)."""
        if node is None:
            return {}
        if not isinstance(node, dict):
            raise self.fail(where, "expected a mapping")
        unknown = [k for k in node if k not in keys]
        if unknown:
            raise self.fail(f"{where}.{unknown[0]}" if where else str(unknown[0]),
                            f"unknown field; expected one of {', '.join(keys)}")
        return node

    def timed(self, node: Any, where: str, key: str, choices: Tuple[str, ...]) -> List[Tuple[float, str]]:
        """``node``, a list of ``{at: seconds, KEY: one of choices}``, as sorted ``(seconds, value)``."""
        if node is None:
            return []
        if not isinstance(node, list):
            raise self.fail(where, f"expected a list of {{at: seconds, {key}: ...}}")
        out = []
        for i, item in enumerate(node):
            item = self.mapping(item, f"{where}[{i}]", ("at", key))
            value = item.get(key)
            if value not in choices:
                raise self.fail(f"{where}[{i}].{key}", f"{value!r} is not a {key} ({', '.join(choices)})")
            out.append((self.value(item.get("at"), f"{where}[{i}].at", 0.0, 86400.0, "s"), str(value)))
        return sorted(out)


def read_map(c: Checker, data: dict, prefix: str, places: Sequence[str],
             default: Mapping[str, Any]) -> Dict[str, Tuple[float, float]]:
    """The episode's ``map``: exactly ``places``, each ``[x, y]`` in metres (``default`` when absent)."""
    given = data.get("map", default)
    if not isinstance(given, dict) or set(given) != set(places):
        raise c.fail(f"{prefix}map", f"expected the places {', '.join(places)} with [x, y] in metres")
    the_map = {}
    for name, xy in given.items():
        if (not isinstance(xy, (list, tuple)) or len(xy) != 2
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in xy)):
            raise c.fail(f"{prefix}map.{name}", f"{xy!r} is not [x, y] in metres")
        the_map[str(name)] = (float(xy[0]), float(xy[1]))
    return the_map


def read_seed_and_steps(c: Checker, data: dict, prefix: str, default_steps: int, most_steps: int) -> Tuple[int, int]:
    """The episode's ``seed`` (an integer, default 0) and ``max_steps`` (in [1, most_steps])."""
    seed = data.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise c.fail(f"{prefix}seed", f"{seed!r} is not an integer")
    steps = data.get("max_steps", default_steps)
    if isinstance(steps, bool) or not isinstance(steps, int) or not 1 <= steps <= most_steps:
        raise c.fail(f"{prefix}max_steps", f"{steps!r} is not an integer in [1, {most_steps}]")
    return seed, steps


def load_episodes(path: Union[str, Path], world: str, episode: Callable[[dict, str, str], S]) -> List[S]:
    """Read the scenario file ``path`` of ``world``: ``episode(fields, source, path prefix)`` per episode
    (the top-level fields with each ``episodes:`` entry merged on top; one episode if none).

    Raises:
        SpecError: not a mapping, another world's file, a bad ``episodes:`` list, or what ``episode`` raises.
    """
    from pearl_pomdp.yaml_lines import load_yaml

    source = str(path)
    data = load_yaml(path)
    if not isinstance(data, dict):
        raise SpecError(source, "", "expected a mapping (a scenario)")
    if data.get("world", world) != world:
        raise SpecError(source, "world", f"{data.get('world')!r}: this file is not for the {world} world")
    episodes = data.get("episodes")
    top = {k: v for k, v in data.items() if k != "episodes"}
    if episodes is None:
        return [episode(top, source, "")]
    if not isinstance(episodes, list) or not episodes:
        raise SpecError(source, "episodes", "expected a non-empty list of episode overrides")
    out = []
    for i, ep in enumerate(episodes):
        if not isinstance(ep, dict):
            raise SpecError(source, f"episodes[{i}]", "expected a mapping of overrides")
        out.append(episode(merge(top, ep), source, f"episodes[{i}]."))
    return out
