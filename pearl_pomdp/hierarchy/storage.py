"""Saving and loading a hierarchical policy: the directory format.

Persistence (``save`` / :func:`load_hierarchical_policy`): a directory with
``policy.npz`` (arrays only, loaded with ``allow_pickle=False``) and ``hierarchy.json``
(structure, sizes, the model fingerprint and the npz's SHA-256), each written to a
temporary file and renamed into place, the JSON last.
"""
from __future__ import annotations

import hashlib
import io
import json
from pathlib import Path
from typing import Any, Dict, Tuple, Union

import numpy as np

from pearl_pomdp.atomic import atomic_write
from pearl_pomdp.errors import PolicyError
from pearl_pomdp.hierarchy.subtask import SubtaskPolicy
from pearl_pomdp.jsonable import numpy_to_json
from pearl_pomdp.policies.lookahead import Lookahead

__all__ = ["write_policy_dir", "read_policy_dir", "FORMAT_VERSION"]

FORMAT_VERSION = 1
NPZ_NAME = "policy.npz"
JSON_NAME = "hierarchy.json"


def write_policy_dir(directory: Union[str, Path], policy: Any) -> Path:
    """Write ``policy.npz`` + ``hierarchy.json`` for ``policy`` (a
    :class:`~pearl_pomdp.hierarchy.execute.HierarchicalPolicy`) into ``directory`` (created),
    atomically per file, the JSON last.

    Returns:
        The directory.
    """
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    arrays = {}
    subtasks = []
    for i, (name, sub) in enumerate(policy.subtasks.items()):
        key = f"s{i}"
        arrays[f"{key}_alphas"] = sub.alphas
        arrays[f"{key}_alpha_actions"] = sub.alpha_actions
        arrays[f"{key}_state_to_model"] = sub.state_to_model
        arrays[f"{key}_effective"] = sub.effective
        if sub.lookahead is not None:
            arrays.update(sub.lookahead.arrays(f"{key}_la"))
        entry = {"name": name, "key": key, "actions": sub.actions, "abstract": sub.abstract, "info": sub.info}
        if sub.lookahead is not None:
            entry["lookahead"] = {"depth": sub.lookahead.depth, "discount": sub.lookahead.discount}
        if sub.contingent:
            entry["contingent"] = {"model_actions": sub.model_actions, "exit": sub.exit,
                                   "search_depth": sub.search_depth, "expansions": sub.expansions}
        if sub.online is not None:
            entry["online"] = sub.online
        subtasks.append(entry)
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)  # type: ignore[arg-type]  # numpy stubs type **kwds as allow_pickle
    npz_bytes = buffer.getvalue()
    digest = hashlib.sha256(npz_bytes).hexdigest()
    header = {
        "format": "pearl-hierarchical-policy", "version": FORMAT_VERSION,
        "model_fingerprint": policy.fingerprint, "model_name": policy.model_name,
        "hierarchy": policy.hierarchy_name, "root": policy.root, "actions": policy.action_names,
        "num_states": policy.num_states, "npz_sha256": digest, "subtasks": subtasks, "report": policy.report,
    }
    atomic_write(d / NPZ_NAME, npz_bytes)
    atomic_write(d / JSON_NAME, json.dumps(header, indent=1, default=numpy_to_json) + "\n")
    return d


def read_policy_dir(directory: Union[str, Path], model: Any) -> Tuple[dict, Dict[str, SubtaskPolicy]]:
    """Read a directory :func:`write_policy_dir` wrote and check it belongs to ``model`` (a flat
    :class:`~pearl_pomdp.model.pomdp.Pomdp`): ``(header, subtask name → SubtaskPolicy)``.

    Raises:
        PolicyError: missing/corrupt files, a checksum mismatch, or a model-fingerprint
            mismatch (the message names the file and what differs).
    """
    d = Path(directory)
    jpath, npath = d / JSON_NAME, d / NPZ_NAME
    if not jpath.is_file() or not npath.is_file():
        raise PolicyError(f"{d}: not a hierarchical policy directory (expected {JSON_NAME} and {NPZ_NAME})")
    try:
        header = json.loads(jpath.read_text())
    except (OSError, ValueError) as err:
        raise PolicyError(f"{jpath}: unreadable JSON header: {err}") from None
    if header.get("format") != "pearl-hierarchical-policy":
        raise PolicyError(f"{jpath}: format is {header.get('format')!r}, expected 'pearl-hierarchical-policy'")
    if header.get("version") != FORMAT_VERSION:
        raise PolicyError(f"{jpath}: version {header.get('version')!r} is not supported (expected {FORMAT_VERSION})")
    raw = npath.read_bytes()
    if hashlib.sha256(raw).hexdigest() != header.get("npz_sha256"):
        raise PolicyError(f"{npath}: SHA-256 does not match {jpath.name} (the pair was not written together)")
    fp = model.fingerprint()
    if fp != header.get("model_fingerprint"):
        raise PolicyError(f"{jpath}: the policy was planned for model {header.get('model_name')!r} with fingerprint "
                          f"{str(header.get('model_fingerprint'))[:12]}…, but the given model {model.name!r} has "
                          f"{fp[:12]}… (re-run `pearl plan`)")
    if list(header.get("actions", [])) != list(model.actions):
        raise PolicyError(f"{jpath}: the policy's actions differ from the model's")
    try:
        with np.load(npath, allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
    except (OSError, ValueError) as err:
        raise PolicyError(f"{npath}: unreadable arrays: {err}") from None
    subtasks = {}
    for entry in header["subtasks"]:
        key = entry["key"]
        contingent = entry.get("contingent") or {}
        try:
            search = None
            if entry.get("lookahead"):
                spec = entry["lookahead"]
                search = Lookahead.from_arrays(arrays, f"{key}_la", float(spec["discount"]), arrays[f"{key}_alphas"],
                                               int(spec["depth"]))
            subtasks[entry["name"]] = SubtaskPolicy(
                name=entry["name"], actions=list(entry["actions"]), abstract=[bool(x) for x in entry["abstract"]],
                alphas=arrays[f"{key}_alphas"], alpha_actions=arrays[f"{key}_alpha_actions"],
                state_to_model=arrays[f"{key}_state_to_model"], effective=arrays[f"{key}_effective"],
                info=entry.get("info", {}), lookahead=search,
                model_actions=None if not contingent else list(contingent["model_actions"]),
                exit=bool(contingent.get("exit", False)), search_depth=int(contingent.get("search_depth", 1)),
                expansions=int(contingent.get("expansions", 256)), online=entry.get("online"))
        except KeyError as err:
            raise PolicyError(f"{npath}: missing array {err} for subtask {entry['name']!r}") from None
        except (ValueError, TypeError, IndexError) as err:
            raise PolicyError(f"{npath}: inconsistent arrays for subtask {entry['name']!r}: {err}") from None
    if header["root"] not in subtasks:
        raise PolicyError(f"{jpath}: root {header['root']!r} is not among the subtasks")
    return header, subtasks
