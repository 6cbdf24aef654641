"""The one YAML loader of Pearl POMDP: safe, YAML 1.2 booleans, and the line of every key.

Domain, hierarchy, scenario and params files all go through :func:`parse_yaml`, so every
error can name the file *and the line*:

* Only the safe subset (``yaml.SafeLoader``): no Python objects from a file a user gives.
* YAML 1.2 booleans: ``yes``/``no``/``on``/``off`` stay strings (Pearl uses ``yes``/``no``
  as feature values and speech symbols; YAML 1.1 would silently make them booleans).
  ``true``/``false`` are booleans.
* Duplicate keys are errors (YAML would silently keep only the last one).
* Mappings and sequences come back as :class:`LineMap` (a ``dict``) and :class:`LineSeq`
  (a ``list``) that remember the 1-based line of themselves and of each key/item
  (:func:`line_of`); :func:`line_table` flattens that to ``{"a.b[2].c": line}``.
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Dict, List, Optional, Union

import yaml

from pearl_pomdp.errors import SpecError

__all__ = ["LineMap", "LineSeq", "line_of", "line_table", "parse_yaml", "load_yaml"]

class LineMap(dict):
    """A mapping that remembers the 1-based line of each key (``lines``) and of itself (``line``)."""

    line: Optional[int] = None

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.lines: Dict[Any, int] = {}


class LineSeq(list):
    """A sequence that remembers the line of each item (``lines``) and of itself (``line``)."""

    line: Optional[int] = None

    def __init__(self, *args):
        super().__init__(*args)
        self.lines: List[int] = []


class _Loader(yaml.SafeLoader):
    """SafeLoader with YAML 1.2 booleans (``yes``/``no``/``on``/``off`` stay strings) and line marks.

    Pearl's domain uses ``yes``/``no`` as feature values and speech symbols; YAML 1.1
    would silently turn them into booleans.
    """


_Loader.yaml_implicit_resolvers = {
    ch: [(tag, rx) for tag, rx in resolvers if tag != "tag:yaml.org,2002:bool"]
    for ch, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:bool", re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"), list("tTfF"))


def _construct_map(loader: yaml.SafeLoader, node: yaml.MappingNode) -> LineMap:
    loader.flatten_mapping(node)
    out = LineMap()
    out.line = node.start_mark.line + 1
    for key_node, value_node in node.value:
        key = loader.construct_object(key_node, deep=True)
        try:
            hash(key)
        except TypeError:
            raise SpecError(loader.name, "", f"unhashable mapping key {key!r}", line=key_node.start_mark.line + 1) from None
        if key in out:
            raise SpecError(loader.name, str(key), "duplicate key (YAML would silently keep only the last one)",
                            line=key_node.start_mark.line + 1)
        out[key] = loader.construct_object(value_node, deep=True)
        out.lines[key] = key_node.start_mark.line + 1
    return out


def _construct_seq(loader: yaml.SafeLoader, node: yaml.SequenceNode) -> LineSeq:
    out = LineSeq()
    out.line = node.start_mark.line + 1
    for item in node.value:
        out.append(loader.construct_object(item, deep=True))
        out.lines.append(item.start_mark.line + 1)
    return out


_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_map)
_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_SEQUENCE_TAG, _construct_seq)

#: The same loader on libyaml's parser when PyYAML has it: scanning and parsing in C is ~10x
#: faster (Pearl's domain: 0.86 → 0.1 s, paid by every node at start-up and every plan). The
#: resolvers and constructors are the Python ones above, so the result is the same; a file the
#: C parser refuses is parsed again by the pure-Python one, whose message :func:`parse_yaml` gives.
_FastLoader: Optional[type] = None
if getattr(yaml, "__with_libyaml__", False):
    class _CLoader(yaml.CSafeLoader):   # type: ignore[misc,valid-type]
        """:class:`_Loader` on libyaml's parser."""

    _CLoader.yaml_implicit_resolvers = _Loader.yaml_implicit_resolvers
    _CLoader.yaml_constructors = _Loader.yaml_constructors
    _FastLoader = _CLoader


def line_of(container: Any, key: Any = None) -> Optional[int]:
    if key is not None:
        lines = getattr(container, "lines", None)
        if isinstance(lines, dict) and key in lines:
            return lines[key]
        if isinstance(lines, list) and isinstance(key, int) and 0 <= key < len(lines):
            return lines[key]
    return getattr(container, "line", None)



def _load_with(loader_class: type, text: str, source: str) -> Any:
    loader = loader_class(text)
    loader.name = source
    try:
        return loader.get_single_data()
    finally:
        loader.dispose()


def parse_yaml(text: str, source: str = "<string>") -> Any:
    """Parse YAML text with :class:`LineMap`/:class:`LineSeq` containers (see the module doc).

    Raises:
        SpecError: not valid YAML, or a duplicate/unhashable key (file and line named).
    """
    if _FastLoader is not None:
        try:
            return _load_with(_FastLoader, text, source)
        except yaml.YAMLError:
            pass   # the pure-Python parser below says what is wrong, in its words and with its line
    try:
        return _load_with(_Loader, text, source)
    except yaml.MarkedYAMLError as err:
        mark = err.problem_mark or err.context_mark
        line = mark.line + 1 if mark is not None else None
        raise SpecError(source, "", f"YAML syntax: {err.problem or err}", line=line) from None
    except yaml.YAMLError as err:
        raise SpecError(source, "", f"YAML syntax: {err}") from None


def load_yaml(path: Union[str, Path]) -> Any:
    """:func:`parse_yaml` of a file (``FileNotFoundError`` when it does not exist)."""
    p = Path(path)
    return parse_yaml(p.read_text(encoding="utf-8"), str(p))


def line_table(data: Any) -> Dict[str, int]:
    """``{"a.b[2].c": line}`` for every key and item of parsed ``data`` (1-based lines).

    A container reached again through a YAML alias is not walked again: its lines are
    those of its anchor, and a small file of nested aliases ("billion laughs") would
    otherwise take exponential time and memory.
    """
    out: Dict[str, int] = {}
    seen: set = set()

    def walk(node: Any, path: str) -> None:
        if not isinstance(node, (dict, list)):
            return
        if id(node) in seen:
            return
        seen.add(id(node))
        items = node.items() if isinstance(node, dict) else enumerate(node)
        for key, value in items:
            sub = (f"{path}.{key}" if path else str(key)) if isinstance(node, dict) else f"{path}[{key}]"
            line = line_of(node, key)
            if line is not None:
                out.setdefault(sub, line)
            walk(value, sub)

    walk(data, "")
    return out
