"""SROS2 access-control policies for a launched graph (docs/reliability.md, "Who may command the robot").

ROS 2's security (SROS2) grants each *enclave* — a set of keys a process starts with
(``--ros-args --enclave PATH``) — the topics it may publish or subscribe, the services it may
serve (``reply``) or call (``request``) and the actions it may serve (``execute``) or call. The
policy file is SROS2's XML (``<policy version="0.2.0"><enclaves><enclave path=…><profiles>
<profile ns=… node=…>``); ``ros2 security create_permission`` turns it into each enclave's signed
DDS permissions. This module is the ROS-free half of ``pearl security policy``:

* :class:`NodeEndpoints` — what one node uses, as fully qualified names;
* :func:`fold_actions` — an action's hidden ``/_action/`` topics and services become one action;
* :func:`build_policy` — one enclave per node (``/pearl/<node>``), plus the operator's enclave,
  the only one allowed to publish the operator's veto and command or call the operator services;
* :func:`read_policy` — the grants of a policy file, names resolved as SROS2 resolves them
  (``/abs`` as is, ``~/x`` under the node, ``rel`` under the namespace);
* :func:`policy_problems` — the rules of SROS2's policy schema (``policy.xsd``, version 0.2.0)
  checked by hand: the schema ships with the ``sros2`` package, which PyPI does not carry, so
  nothing here can validate against the file itself;
* :func:`security_notice` — the one line the operator-facing node logs when DDS security is off.

Names are written absolute, except a node's private ones (``~/get_state``), so one file reads the
same under any working directory and a reviewer sees the exact topic.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field, replace
from typing import Dict, FrozenSet, Iterable, List, Mapping, Optional, Sequence, Tuple

from pearl_pomdp.errors import SpecError

__all__ = ["POLICY_VERSION", "ENCLAVE_PREFIX", "OPERATOR_NODE", "OPERATOR_PARAMETERS", "NodeEndpoints",
           "fold_actions", "renamed", "operator_endpoints", "build_policy", "read_policy", "policy_problems",
           "security_notice"]

#: The policy format version SROS2's schema fixes (``<policy version="0.2.0">``).
POLICY_VERSION = "0.2.0"

#: Every node's enclave is ``/pearl/<node name>``; the operator's is ``/pearl/operator``.
ENCLAVE_PREFIX = "/pearl"

#: The node name an operator's console runs under (``--ros-args -r __node:=pearl_operator
#: --enclave /pearl/operator``): the profile of the operator's enclave.
OPERATOR_NODE = "pearl_operator"

#: The policy node's parameters that name what an operator uses, by what the operator does with
#: each: publish (veto, command), subscribe (what waits for a yes, what happened) and call (the
#: services). Only the operator's enclave is granted to publish the veto and command topics.
OPERATOR_PARAMETERS: Mapping[str, Tuple[str, ...]] = {
    "publishes": ("veto_topic", "command_topic"),
    "subscribes": ("proposal_topic", "operator_events_topic"),
    "calls": ("confirm_service", "set_autonomy_service", "veto_service", "command_service"),
}

RULES = ("ALLOW", "DENY")

#: (list element, item element, {attribute: NodeEndpoints field}) for each kind of grant, in file order.
GRANTS: Tuple[Tuple[str, str, Tuple[Tuple[str, str], ...]], ...] = (
    ("topics", "topic", (("publish", "publishes"), ("subscribe", "subscribes"))),
    ("services", "service", (("reply", "serves"), ("request", "calls"))),
    ("actions", "action", (("execute", "executes"), ("call", "invokes"))),
)
FIELDS = tuple(f for _, _, pairs in GRANTS for _, f in pairs)

ACTION_SERVICES = ("send_goal", "cancel_goal", "get_result")
ACTION_TOPICS = ("feedback", "status")
ACTION_MARK = "/_action/"


@dataclass(frozen=True)
class NodeEndpoints:
    """The endpoints of one node, each a fully qualified name (``/pearl/belief``).

    Attributes:
        name, namespace: the node's name and namespace (``/``: none).
        publishes, subscribes: topics.
        serves, calls: services it replies to (a server) or requests (a client).
        executes, invokes: actions it serves or calls.
    """

    name: str
    namespace: str = "/"
    publishes: FrozenSet[str] = field(default_factory=frozenset)
    subscribes: FrozenSet[str] = field(default_factory=frozenset)
    serves: FrozenSet[str] = field(default_factory=frozenset)
    calls: FrozenSet[str] = field(default_factory=frozenset)
    executes: FrozenSet[str] = field(default_factory=frozenset)
    invokes: FrozenSet[str] = field(default_factory=frozenset)

    @property
    def fully_qualified_name(self) -> str:
        """``/ns/name`` (``/name`` in the root namespace)."""
        return _join(self.namespace, self.name)

    def grants(self) -> Dict[str, FrozenSet[str]]:
        """``{field: names}`` for the six kinds of grant."""
        return {f: getattr(self, f) for f in FIELDS}


def _join(namespace: str, name: str) -> str:
    return (namespace.rstrip("/") + "/" + name) if name else namespace


def fold_actions(node: NodeEndpoints) -> NodeEndpoints:
    """``node`` with each action's hidden parts (``X/_action/send_goal`` … services,
    ``X/_action/feedback`` and ``status`` topics) replaced by the action ``X`` (SROS2 grants an
    action as one ``<action>``). A server serves ``send_goal``; a client calls it."""
    def parts(names: Iterable[str], suffixes: Sequence[str]) -> Dict[str, set]:
        found: Dict[str, set] = {}
        for n in names:
            head, mark, tail = n.rpartition(ACTION_MARK)
            if mark and tail in suffixes:
                found.setdefault(head, set()).add(tail)
        return found

    served = {a for a, s in parts(node.serves, ACTION_SERVICES).items() if s == set(ACTION_SERVICES)}
    called = {a for a, s in parts(node.calls, ACTION_SERVICES).items() if s == set(ACTION_SERVICES)}

    def strip(names: FrozenSet[str], actions: set, suffixes: Sequence[str]) -> FrozenSet[str]:
        hidden = {f"{a}{ACTION_MARK}{s}" for a in actions for s in suffixes}
        return frozenset(names - hidden)

    return replace(node,
                   serves=strip(node.serves, served, ACTION_SERVICES),
                   calls=strip(node.calls, called, ACTION_SERVICES),
                   publishes=strip(node.publishes, served, ACTION_TOPICS),
                   subscribes=strip(node.subscribes, called, ACTION_TOPICS),
                   executes=node.executes | served, invokes=node.invokes | called)


def renamed(node: NodeEndpoints, name: str, namespace: str = "/") -> NodeEndpoints:
    """``node``'s endpoints as another node ``namespace/name`` would have them: its private names
    (``/its/name/x``) move to the new node, the others stay."""
    old, own = node.fully_qualified_name + "/", _join(namespace, name) + "/"
    return NodeEndpoints(name, namespace, **{f: frozenset(own + n[len(old):] if n.startswith(old) else n
                                                          for n in names) for f, names in node.grants().items()})


def operator_endpoints(policy_parameters: Mapping[str, str], bare_node: NodeEndpoints,
                       namespace: str = "/") -> NodeEndpoints:
    """The operator console's grants (node :data:`OPERATOR_NODE`): the operator's topics and
    services named by the policy node's parameters (``policy_parameters``: the names of
    :data:`OPERATOR_PARAMETERS` → fully qualified names), plus what ``bare_node`` — a ROS node of
    this install that created nothing itself — declares by itself (``/rosout``,
    ``/parameter_events``, its parameter services), which the console, a ROS node too, needs.

    Raises:
        SpecError: a parameter of :data:`OPERATOR_PARAMETERS` is missing from ``policy_parameters``.
    """
    missing = [p for names in OPERATOR_PARAMETERS.values() for p in names if p not in policy_parameters]
    if missing:
        raise SpecError("hierarchical_policy", "parameters", f"{', '.join(missing)} not found: the operator's grants "
                        "cannot be named")
    grants = {f: set(names) for f, names in renamed(bare_node, OPERATOR_NODE, namespace).grants().items()}
    for f, params in OPERATOR_PARAMETERS.items():
        grants[f] |= {policy_parameters[p] for p in params}
    return NodeEndpoints(OPERATOR_NODE, namespace, **{f: frozenset(v) for f, v in grants.items()})


def _relative(name: str, node: NodeEndpoints) -> str:
    prefix = node.fully_qualified_name + "/"
    return "~/" + name[len(prefix):] if name.startswith(prefix) else name


def _resolve(expression: str, node: str, namespace: str) -> str:
    """A policy expression as SROS2's permissions template resolves it."""
    if expression.startswith("/"):
        return expression
    if expression.startswith("~"):
        return _join(namespace, node) + expression[1:]
    return _join(namespace, expression)


def build_policy(nodes: Iterable[NodeEndpoints], operator: Optional[NodeEndpoints] = None,
                 prefix: str = ENCLAVE_PREFIX, comment: str = "",
                 enclaves: Optional[Mapping[str, str]] = None) -> str:
    """The SROS2 policy XML: each node's profile granting exactly its endpoints (ALLOW) in its
    enclave — ``enclaves[fully qualified name]`` (what ``--enclave`` the node was started with),
    else ``prefix/<node>`` — and the operator's profile in ``prefix/operator`` when ``operator``
    is given. Enclaves sorted by path, profiles by node; ``comment`` goes first (how it was made)."""
    if "--" in comment:
        raise ValueError(f"an XML comment cannot hold '--': {comment!r}")
    chosen = dict(enclaves or {})
    grouped: Dict[str, List[NodeEndpoints]] = {}
    for node in nodes:
        path = chosen.get(node.fully_qualified_name) or "/"
        grouped.setdefault(path if path != "/" else f"{prefix}/{node.name}", []).append(node)
    entries = sorted(grouped.items())
    if operator is not None:
        entries.append((f"{prefix}/operator", [operator]))
    root = ET.Element("policy", version=POLICY_VERSION)
    parent = ET.SubElement(root, "enclaves")
    for path, members in entries:
        profiles = ET.SubElement(ET.SubElement(parent, "enclave", path=path), "profiles")
        for node in sorted(members, key=lambda n: n.fully_qualified_name):
            profile = ET.SubElement(profiles, "profile", ns=node.namespace, node=node.name)
            for list_tag, item_tag, pairs in GRANTS:
                for attribute, f in pairs:
                    names = getattr(node, f)
                    if names:
                        grant = ET.SubElement(profile, list_tag, {attribute: "ALLOW"})
                        for name in sorted(_relative(n, node) for n in names):
                            ET.SubElement(grant, item_tag).text = name
    ET.indent(root, space="  ")
    head = '<?xml version="1.0" encoding="UTF-8"?>\n'
    if comment:
        head += "<!--\n" + "\n".join(f"  {line}".rstrip() for line in comment.splitlines()) + "\n-->\n"
    return head + ET.tostring(root, encoding="unicode") + "\n"


def read_policy(text: str, source: str = "<policy>") -> List[Tuple[str, NodeEndpoints]]:
    """``[(enclave path, the profile's ALLOW grants as fully qualified names)]``, one per profile.

    Raises:
        SpecError: not XML, or against the policy schema (:func:`policy_problems`; the first
            problem, naming ``source``), or a DENY rule (this reader grants; it does not subtract).
    """
    try:
        root = ET.fromstring(text)
    except ET.ParseError as err:
        raise SpecError(source, "", f"not XML: {err}") from None
    problems = policy_problems(root)
    if problems:
        raise SpecError(source, "", problems[0])
    found = []
    for enclave in root.iter("enclave"):
        for profile in enclave.iter("profile"):
            ns, name = profile.get("ns", "/"), profile.get("node", "")
            grants: Dict[str, set] = {f: set() for f in FIELDS}
            for list_tag, item_tag, pairs in GRANTS:
                for grant in profile.findall(list_tag):
                    for attribute, f in pairs:
                        rule = grant.get(attribute)
                        if rule == "DENY":
                            raise SpecError(source, f"enclave {enclave.get('path')}", f"<{list_tag} {attribute}=\"DENY\">: "
                                            "this reader takes ALLOW rules only")
                        if rule == "ALLOW":
                            grants[f] |= {_resolve((i.text or "").strip(), name, ns) for i in grant.findall(item_tag)}
            found.append((enclave.get("path", ""), NodeEndpoints(name, ns, **{f: frozenset(v) for f, v in grants.items()})))
    return found


def _children_only(el: ET.Element, allowed: Sequence[str], where: str) -> List[str]:
    problems = [f"{where}: unexpected element <{c.tag}> (allowed: {', '.join(allowed)})"
                for c in el if c.tag not in allowed]
    if (el.text or "").strip() or any((c.tail or "").strip() for c in el):
        problems.append(f"{where}: text outside the elements")
    return problems


def _attributes_only(el: ET.Element, allowed: Sequence[str], where: str) -> List[str]:
    xml_base = "{http://www.w3.org/XML/1998/namespace}base"
    return [f"{where}: unexpected attribute {a}" for a in el.attrib if a not in allowed and a != xml_base]


def policy_problems(root: ET.Element) -> List[str]:
    """What makes ``root`` invalid against SROS2's policy schema (``policy.xsd``, 0.2.0), each
    problem naming where: ``policy`` with ``version="0.2.0"`` holding one ``enclaves``; that
    one or more ``enclave`` (``path`` required), each one or more ``profiles`` (optional ``type``:
    one or more ``profile`` then at most one ``metadata``); a ``profile`` (``ns`` and ``node``
    required) holds only ``topics``/``services``/``actions``, each of one or more
    ``topic``/``service``/``action`` expressions (text only) with its two rule attributes
    (``publish``/``subscribe``, ``reply``/``request``, ``execute``/``call``) ALLOW or DENY.
    Empty: valid. Beyond the schema, a grant list that sets no rule is reported (it grants nothing)."""
    if root.tag != "policy":
        return [f"root element <{root.tag}>, expected <policy>"]
    problems = _attributes_only(root, ("version",), "<policy>")
    if root.get("version") != POLICY_VERSION:
        problems.append(f"<policy>: version {root.get('version')!r}, the schema fixes {POLICY_VERSION!r}")
    problems += _children_only(root, ("enclaves",), "<policy>")
    if len(root.findall("enclaves")) != 1:
        problems.append(f"<policy>: {len(root.findall('enclaves'))} <enclaves>, expected exactly 1")
    for enclaves in root.findall("enclaves"):
        problems += _attributes_only(enclaves, (), "<enclaves>") + _children_only(enclaves, ("enclave",), "<enclaves>")
        if not enclaves.findall("enclave"):
            problems.append("<enclaves>: no <enclave>")
        for i, enclave in enumerate(enclaves.findall("enclave")):
            where = f"enclave {enclave.get('path', f'#{i + 1}')}"
            if not enclave.get("path"):
                problems.append(f"{where}: no path attribute")
            problems += _attributes_only(enclave, ("path",), where) + _children_only(enclave, ("profiles",), where)
            if not enclave.findall("profiles"):
                problems.append(f"{where}: no <profiles>")
            for profiles in enclave.findall("profiles"):
                problems += _attributes_only(profiles, ("type",), where) + _children_only(
                    profiles, ("profile", "metadata"), where)
                tags = [c.tag for c in profiles]
                if "profile" not in tags:
                    problems.append(f"{where}: <profiles> holds no <profile>")
                if tags.count("metadata") > 1 or ("metadata" in tags and tags[-1] != "metadata"):
                    problems.append(f"{where}: <metadata> must come once, after the profiles")
                for profile in profiles.findall("profile"):
                    problems += _profile_problems(profile, where)
    return problems


def _profile_problems(profile: ET.Element, enclave: str) -> List[str]:
    where = f"{enclave}: profile {profile.get('node')!r}"
    problems = [f"{where}: no {a} attribute" for a in ("ns", "node") if profile.get(a) is None]
    problems += _attributes_only(profile, ("ns", "node"), where)
    problems += _children_only(profile, [t for t, _, _ in GRANTS], where)
    for list_tag, item_tag, pairs in GRANTS:
        attributes = [a for a, _ in pairs]
        for grant in profile.findall(list_tag):
            at = f"{where}: <{list_tag}>"
            problems += _attributes_only(grant, attributes, at) + _children_only(grant, (item_tag,), at)
            problems += [f"{at}: {a}={grant.get(a)!r}, expected ALLOW or DENY"
                         for a in attributes if grant.get(a) is not None and grant.get(a) not in RULES]
            if not any(grant.get(a) for a in attributes):
                problems.append(f"{at}: sets neither {' nor '.join(attributes)}")
            if not grant.findall(item_tag):
                problems.append(f"{at}: no <{item_tag}>")
            for item in grant.findall(item_tag):
                if len(item) or item.attrib or not (item.text or "").strip():
                    problems.append(f"{at}: <{item_tag}> must hold a name and nothing else")
    return problems


def security_notice(environ: Mapping[str, str], domain_id: int, operator_names: Sequence[str]) -> Optional[str]:
    """The one line the operator-facing node logs at start when DDS security is off
    (``ROS_SECURITY_ENABLE`` is not ``true``), naming what anyone on the domain can then do; ``None``
    when it is on (then the middleware has refused to start the node unless its enclave's keys and
    permissions are there: a node that runs is secured)."""
    if environ.get("ROS_SECURITY_ENABLE", "").strip().lower() == "true":
        return None
    return (f"DDS security is off (ROS_SECURITY_ENABLE is not 'true'): any process on ROS domain {domain_id} "
            f"can publish or call {', '.join(operator_names)}; docs/reliability.md, 'Who may command the robot', "
            "says how to turn SROS2 on")
