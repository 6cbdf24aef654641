"""A ROS-free reader of ROS 2 XML launch files (the subset ``pearl launch`` runs).

``ros2 launch`` (launch / launch_ros) is not on PyPI, so ``pearl launch FILE`` reads the
same XML front-end files and starts their ``<node>`` entries as processes. What is read
is exactly what ``ros2 launch`` understands for these elements, so one file serves both:

* ``<launch>`` — the root.
* ``<arg name default description/>`` — an argument; ``name:=value`` on the command line
  overrides the default; an argument without default must be given.
* ``<let name value/>`` — sets a variable for the following elements.
* ``<group [scoped="true"]>`` with ``<push-ros-namespace namespace="…"/>`` — a scope
  (``let``/``arg`` inside a scoped group do not leak out), optionally namespaced.
* ``<node pkg exec [name] [namespace] [output] [args] [ros_args] [respawn] [respawn_delay] [on_exit="shutdown"]>`` with children
  ``<param name value/>`` (nested ``<param name>`` groups make dotted names),
  ``<param from="params.yaml"/>`` and ``<remap from to/>``.
* ``if="…"`` / ``unless="…"`` on any element (``true``/``false``/``1``/``0``).
* Substitutions in attribute values: ``$(var NAME)``, ``$(find-pkg-share PKG)``,
  ``$(env NAME [DEFAULT])``, ``$(dirname)`` (the launch file's directory).

Anything else (``<include>``, ``$(eval …)``, …) is an error naming the file and line, so a
file that would mean something different under ``ros2 launch`` is never half-run.
Nothing here imports ROS.
"""
from __future__ import annotations

import os
import re
import shlex
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, Iterable, List, Mapping, Optional, Tuple, Union
from xml.parsers import expat

from pearl_pomdp.errors import SpecError

__all__ = ["LaunchDescription", "LaunchNode", "LaunchArg", "parse_launch_file", "parse_launch_text",
           "parse_cli_arguments", "package_share_dir"]

PathLike = Union[str, Path]


# --------------------------------------------------------------------- share dirs
def package_share_dir(package: str) -> Optional[Path]:
    """The ``share/<package>`` directory, as ``$(find-pkg-share package)`` would give it.

    Looked up, in order: the ament index of every prefix in ``AMENT_PREFIX_PATH`` (a colcon
    or apt install); for ``pearl_pomdp``, the source tree this module was imported from (an
    editable install: the directory holding ``package.xml``, ``launch/`` and ``config/``), then
    the ``share/pearl_pomdp`` of the prefix it is installed in;
    ``<sys.prefix>/share/<package>`` (a pip install's data files). ``None`` when none exists.
    """
    for prefix in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
        marker = Path(prefix) / "share" / "ament_index" / "resource_index" / "packages" / package
        if marker.is_file():
            return Path(prefix) / "share" / package
    if package == "pearl_pomdp":
        here = Path(__file__).resolve()
        tree = here.parents[1]
        if (tree / "package.xml").is_file() and (tree / "launch").is_dir():
            return tree
        # An install prefix (colcon or setup.py install): PREFIX/lib/pythonX.Y/site-packages/
        # pearl_pomdp/ beside PREFIX/share/pearl_pomdp, found even before AMENT_PREFIX_PATH is set.
        if len(here.parents) > 4:
            installed = here.parents[4] / "share" / package
            if (installed / "package.xml").is_file():
                return installed
    candidate = Path(sys.prefix) / "share" / package
    return candidate if candidate.is_dir() else None


# --------------------------------------------------------------------- the model
@dataclass
class LaunchArg:
    """A declared ``<arg>``: its default (``None`` = required) and description."""

    name: str
    default: Optional[str]
    description: str = ""


@dataclass
class LaunchNode:
    """One ``<node>`` entry, with every substitution resolved.

    Attributes:
        package, executable: ``pkg`` and ``exec``.
        name, namespace: ``None`` when the file does not set them.
        output: ``screen``, ``log`` or ``both``.
        parameters: in file order, ``("file", path)`` for ``<param from>`` and
            ``("value", name, value)`` for ``<param name value>`` (later ones win, as in ROS).
        remappings: ``(from, to)`` pairs.
        arguments: extra command-line arguments (``args`` attribute), before ``--ros-args``.
        extra_ros_args: the ``ros_args`` attribute, split.
        respawn, respawn_delay: start the node again when it dies, after that many seconds
            (``pearl launch`` bounds the restarts: ``--respawn-max-retries``).
        shutdown_on_exit: ``on_exit="shutdown"``: the node's own exit, whatever its code, ends the
            launch; with ``respawn`` it is started again only when a signal killed it.
        line: the ``<node>`` element's line in the file.
    """

    package: str
    executable: str
    name: Optional[str] = None
    namespace: Optional[str] = None
    output: str = "log"
    parameters: List[tuple] = field(default_factory=list)
    remappings: List[Tuple[str, str]] = field(default_factory=list)
    arguments: List[str] = field(default_factory=list)
    extra_ros_args: List[str] = field(default_factory=list)
    respawn: bool = False
    respawn_delay: float = 0.0
    shutdown_on_exit: bool = False
    line: int = 0

    @property
    def label(self) -> str:
        """The name shown in ``pearl launch`` output (node name, else executable)."""
        return self.name or self.executable

    @property
    def fully_qualified_name(self) -> Optional[str]:
        """``/namespace/name`` when the file names the node, else ``None``."""
        if not self.name:
            return None
        ns = (self.namespace or "").rstrip("/")
        return f"{ns}/{self.name}"

    def ros_args(self, params_dir: Optional[PathLike] = None) -> List[str]:
        """``--ros-args …`` as ``ros2 launch`` would pass them (rename, namespace, params, remaps).

        Like launch_ros, each run of ``<param name value>`` entries is written to a params
        file in ``params_dir`` under the node's fully qualified name (``/**`` if unnamed),
        and all params files are passed in file order, so a later entry wins and a
        ``<param name value>`` beats the same name in an earlier ``<param from>`` file. (A
        plain ``-p`` would not: rcl lets node-specific file entries beat ``-p``.) Without
        ``params_dir`` the values are passed as ``-p name:=value`` (for display only).
        """
        out = ["--ros-args"]
        if self.name:
            out += ["-r", f"__node:={self.name}"]
        if self.namespace:
            out += ["-r", f"__ns:={self.namespace}"]
        groups: List[tuple] = []
        for entry in self.parameters:
            if entry[0] == "file":
                groups.append(entry)
            elif groups and groups[-1][0] == "values":
                groups[-1][1].append(entry[1:])
            else:
                groups.append(("values", [entry[1:]]))
        for index, group in enumerate(groups):
            if group[0] == "file":
                out += ["--params-file", group[1]]
            elif params_dir is None:
                # An empty value is the empty string (rcl rejects a bare ``name:=``).
                out += [a for name, value in group[1] for a in ("-p", f"{name}:={value if value != '' else chr(39) * 2}")]
            else:
                out += ["--params-file", str(self._write_params(Path(params_dir), index, group[1]))]
        for src, dst in self.remappings:
            out += ["-r", f"{src}:={dst}"]
        return out + list(self.extra_ros_args)

    def _write_params(self, params_dir: Path, index: int, values: List[Tuple[str, str]]) -> Path:
        import yaml

        key = self.fully_qualified_name or "/**"
        params = {name: (yaml.safe_load(value) if value.strip() else "") for name, value in values}
        params_dir.mkdir(parents=True, exist_ok=True)
        label = (self.fully_qualified_name or self.executable).strip("/").replace("/", "_")
        path = params_dir / f"{label}_{self.line}_{index}.params.yaml"
        path.write_text(yaml.safe_dump({key: {"ros__parameters": params}}, sort_keys=False), encoding="utf-8")
        return path

    def argv(self, params_dir: Optional[PathLike] = None) -> List[str]:
        """Everything after the executable: ``args`` then :meth:`ros_args`."""
        return list(self.arguments) + self.ros_args(params_dir)


@dataclass
class LaunchDescription:
    """A parsed launch file: its declared arguments, their values and the nodes to start."""

    source: Path
    arguments: Dict[str, LaunchArg]
    values: Dict[str, str]
    nodes: List[LaunchNode]


# --------------------------------------------------------------------- XML with lines
@dataclass
class _Element:
    tag: str
    attrib: Dict[str, str]
    line: int
    children: List["_Element"] = field(default_factory=list)


def _parse_xml(text: str, source: str) -> _Element:
    stack: List[_Element] = []
    root: List[_Element] = []
    parser = expat.ParserCreate()

    def start(tag, attrib):
        el = _Element(tag, dict(attrib), parser.CurrentLineNumber)
        (stack[-1].children if stack else root).append(el)
        stack.append(el)

    def end(tag):
        stack.pop()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    try:
        parser.Parse(text, True)
    except expat.ExpatError as err:
        raise SpecError(source, "", f"not well-formed XML: {expat.ErrorString(err.code)}", line=err.lineno) from None
    return root[0]


# --------------------------------------------------------------------- substitutions
_SUBST = re.compile(r"\$\(([^()]*)\)")


class _Scope:
    def __init__(self, source: Path, values: Dict[str, str]):
        self.source = source
        self.values = values

    def child(self) -> "_Scope":
        return _Scope(self.source, dict(self.values))

    def substitute(self, text: str, el: _Element, attr: str) -> str:
        def repl(m: re.Match) -> str:
            words = m.group(1).split()
            if not words:
                raise self.error(el, attr, f"empty substitution in {text!r}")
            kind, rest = words[0], words[1:]
            if kind == "var" and len(rest) == 1:
                if rest[0] not in self.values:
                    known = ", ".join(sorted(self.values)) or "none"
                    raise self.error(el, attr, f"$(var {rest[0]}): no such argument or variable (known: {known})")
                return self.values[rest[0]]
            if kind == "find-pkg-share" and len(rest) == 1:
                share = package_share_dir(rest[0])
                if share is None:
                    raise self.error(el, attr, f"$(find-pkg-share {rest[0]}): package not found "
                                               f"(AMENT_PREFIX_PATH, source tree, {sys.prefix}/share)")
                return str(share)
            if kind == "env" and len(rest) in (1, 2):
                value = os.environ.get(rest[0], rest[1] if len(rest) == 2 else None)
                if value is None:
                    raise self.error(el, attr, f"$(env {rest[0]}): not set and no default")
                return value
            if kind == "dirname" and not rest:
                return str(self.source.resolve().parent)
            raise self.error(el, attr, f"unsupported substitution $({m.group(1)}) (pearl launch supports "
                                       f"var, find-pkg-share, env, dirname)")

        return _SUBST.sub(repl, text)

    def error(self, el: _Element, attr: str, problem: str) -> SpecError:
        where = f"<{el.tag}>" + (f".{attr}" if attr else "")
        return SpecError(self.source, where, problem, line=el.line)

    def attr(self, el: _Element, name: str, default: Optional[str] = None) -> Optional[str]:
        """Attribute ``name`` with its substitutions done, or ``default`` when it is absent."""
        if name not in el.attrib:
            return default
        return self.substitute(el.attrib[name], el, name)

    def need(self, el: _Element, name: str, default: Optional[str] = None) -> str:
        """Attribute ``name`` with its substitutions done; absent: ``default``, or an error naming it."""
        if name not in el.attrib:
            if default is None:
                raise self.error(el, name, "missing attribute")
            return default
        return self.substitute(el.attrib[name], el, name)


_TRUE = {"true", "1"}
_FALSE = {"false", "0"}
_NODE_ATTRS = {"pkg", "exec", "name", "namespace", "output", "args", "ros_args", "if", "unless",
               "respawn", "respawn_delay", "emulate_tty", "exec_name", "on_exit"}


def _condition(scope: _Scope, el: _Element) -> bool:
    for key, want in (("if", True), ("unless", False)):
        if key in el.attrib:
            value = scope.need(el, key).strip().lower()
            if value not in _TRUE | _FALSE:
                raise scope.error(el, key, f"condition must be true/false/1/0, got {value!r}")
            if (value in _TRUE) != want:
                return False
    return True


def _check_attrs(scope: _Scope, el: _Element, allowed: Iterable[str]) -> None:
    allowed = set(allowed) | {"if", "unless"}
    for key in el.attrib:
        if key not in allowed:
            raise scope.error(el, key, f"unknown attribute (allowed: {', '.join(sorted(allowed))})")


# --------------------------------------------------------------------- parsing
def parse_cli_arguments(items: Iterable[str]) -> Dict[str, str]:
    """``["a:=1", "b:=x"]`` → ``{"a": "1", "b": "x"}`` (the ``ros2 launch`` argument syntax).

    Raises:
        SpecError: an item is not ``name:=value``.
    """
    out = {}
    for item in items:
        name, sep, value = item.partition(":=")
        if not sep or not name:
            raise SpecError("<command line>", "", f"launch argument {item!r} is not name:=value")
        out[name] = value
    return out


def parse_launch_file(path: PathLike, arguments: Optional[Mapping[str, str]] = None) -> LaunchDescription:
    """Read a launch file; ``arguments`` are the ``name:=value`` overrides.

    Raises:
        FileNotFoundError: no such file.
        SpecError: malformed XML, an unsupported element, a missing argument … (file:line).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(2, "no such launch file", str(path))
    return parse_launch_text(path.read_text(encoding="utf-8"), path, arguments)


def parse_launch_text(text: str, source: PathLike = "<string>", arguments: Optional[Mapping[str, str]] = None
                      ) -> LaunchDescription:
    """Like :func:`parse_launch_file`, from a string (``$(dirname)`` is relative to ``source``)."""
    source = Path(source)
    root = _parse_xml(text, str(source))
    given = dict(arguments or {})
    scope = _Scope(source, {})
    if root.tag != "launch":
        raise scope.error(root, "", "the root element must be <launch>")
    declared: Dict[str, LaunchArg] = {}
    nodes: List[LaunchNode] = []
    _walk(root.children, scope, given, declared, nodes, namespace=None)
    unknown = sorted(set(given) - set(declared))
    if unknown:
        known = ", ".join(sorted(declared)) or "none"
        raise SpecError(source, "", f"unknown launch argument(s) {', '.join(unknown)} (declared: {known})")
    values = {name: scope.values[name] for name in declared if name in scope.values}
    return LaunchDescription(source, declared, values, nodes)


def _walk(elements: List[_Element], scope: _Scope, given: Dict[str, str], declared: Dict[str, LaunchArg],
          nodes: List[LaunchNode], namespace: Optional[str]) -> None:
    for el in elements:
        if not _condition(scope, el):
            continue
        if el.tag == "arg":
            _check_attrs(scope, el, {"name", "default", "description"})
            name = scope.need(el, "name")
            default = scope.attr(el, "default")
            declared[name] = LaunchArg(name, default, el.attrib.get("description", ""))
            if name in given:
                scope.values[name] = given[name]
            elif default is not None:
                scope.values[name] = default
            else:
                raise scope.error(el, "name", f"argument {name!r} has no default and was not given "
                                              f"(pass {name}:=VALUE)")
        elif el.tag == "let":
            _check_attrs(scope, el, {"name", "value"})
            scope.values[scope.need(el, "name")] = scope.need(el, "value")
        elif el.tag == "group":
            _check_attrs(scope, el, {"scoped", "forwarding"})
            scoped = (scope.attr(el, "scoped", default="true") or "true").lower() in _TRUE
            inner = scope.child() if scoped else scope
            ns = namespace
            body = []
            for child in el.children:
                if child.tag in ("push-ros-namespace", "push_ros_namespace"):
                    _check_attrs(inner, child, {"namespace"})
                    if _condition(inner, child):
                        part = inner.need(child, "namespace").strip("/")
                        ns = f"{ns.rstrip('/') if ns else ''}/{part}"
                else:
                    body.append(child)
            _walk(body, inner, given, declared, nodes, ns)
        elif el.tag == "node":
            nodes.append(_node(el, scope, namespace))
        else:
            raise scope.error(el, "", "unsupported element (pearl launch reads arg, let, group, "
                                      "push-ros-namespace, node, param, remap)")


def _node(el: _Element, scope: _Scope, namespace: Optional[str]) -> LaunchNode:
    _check_attrs(scope, el, _NODE_ATTRS)
    node = LaunchNode(package=scope.need(el, "pkg"), executable=scope.need(el, "exec"),
                      name=scope.attr(el, "name"), output=scope.need(el, "output", default="log"), line=el.line)
    if node.output not in ("screen", "log", "both"):
        raise scope.error(el, "output", f"must be screen, log or both, got {node.output!r}")
    # ros2 launch ends the launch when such a node exits; so does pearl launch (a respawn node only
    # when it exits by itself: killed by a signal it is started again).
    if "on_exit" in el.attrib:
        if scope.attr(el, "on_exit") != "shutdown":
            raise scope.error(el, "on_exit", f"only 'shutdown' is supported, got {scope.attr(el, 'on_exit')!r}")
        node.shutdown_on_exit = True
    own_ns = scope.attr(el, "namespace")
    if own_ns and own_ns.startswith("/"):
        node.namespace = own_ns
    elif own_ns or namespace:
        parts = [p.strip("/") for p in (namespace, own_ns) if p]
        node.namespace = "/" + "/".join(p for p in parts if p)
    if "respawn" in el.attrib:
        value = scope.need(el, "respawn").strip().lower()
        if value not in _TRUE | _FALSE:
            raise scope.error(el, "respawn", f"must be true/false/1/0, got {value!r}")
        node.respawn = value in _TRUE
    if "respawn_delay" in el.attrib:
        text = scope.need(el, "respawn_delay")
        try:
            node.respawn_delay = float(text)
        except ValueError:
            raise scope.error(el, "respawn_delay", f"must be seconds, got {text!r}") from None
        if not node.respawn_delay >= 0:
            raise scope.error(el, "respawn_delay", f"must be >= 0 s, got {text!r}")
    if "args" in el.attrib:
        node.arguments = shlex.split(scope.attr(el, "args"))
    if "ros_args" in el.attrib:
        node.extra_ros_args = shlex.split(scope.attr(el, "ros_args"))
    for child in el.children:
        if not _condition(scope, child):
            continue
        if child.tag == "param":
            _param(child, scope, node, prefix="")
        elif child.tag == "remap":
            _check_attrs(scope, child, {"from", "to"})
            node.remappings.append((scope.need(child, "from"), scope.need(child, "to")))
        else:
            raise scope.error(child, "", "unsupported element inside <node> (param, remap)")
    return node


def _param(el: _Element, scope: _Scope, node: LaunchNode, prefix: str) -> None:
    _check_attrs(scope, el, {"name", "value", "from", "allow_substs", "sep", "value-sep"})
    if "from" in el.attrib:
        if "name" in el.attrib or "value" in el.attrib:
            raise scope.error(el, "from", "a <param from=…> takes no name or value")
        path = Path(scope.need(el, "from"))
        if not path.is_absolute():
            path = scope.source.resolve().parent / path if not path.exists() else path.resolve()
        if not path.is_file():
            raise scope.error(el, "from", f"no such parameters file: {path}")
        node.parameters.append(("file", str(path)))
        return
    name = scope.need(el, "name")
    full = f"{prefix}{name}"
    if "value" in el.attrib:
        if el.children:
            raise scope.error(el, "value", "a <param> has either a value or nested <param>s")
        node.parameters.append(("value", full, scope.attr(el, "value")))
        return
    if not el.children:
        raise scope.error(el, "value", f"parameter {full!r} has no value")
    for child in el.children:
        if child.tag != "param":
            raise scope.error(child, "", "only <param> may be nested in <param>")
        if _condition(scope, child):
            _param(child, scope, node, prefix=f"{full}.")
