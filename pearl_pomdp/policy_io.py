"""Policy files: arrays in ``.npz`` (no pickle) plus a JSON header beside them.

A saved policy is two files:

* ``PATH`` — a NumPy ``.npz`` archive holding only numeric arrays (read with
  ``allow_pickle=False``):

  - α-vector policy (:class:`~pearl_pomdp.solution.AlphaVectorPolicy`):
    ``alphas [K, S]`` float, ``actions [K]`` int (action index of each vector);
  - most-likely-state policy (``MostLikelyStatePolicy``): ``state_actions [S]`` int.

* ``PATH`` with its suffix replaced by ``.json`` (``tiger.npz`` → ``tiger.json``) — the header::

      {"format": "pearl-policy", "format_version": 1, "kind": "alpha_vectors",
       "model_name": "tiger.95", "model_fingerprint": "<sha256>", "states": 2, "actions": 3,
       "observations": 2, "action_names": [...], "method": "incprune", "value_at_start": 19.37,
       "upper_bound": null, "solve_seconds": 0.8, "created": "2026-11-23T20:00:00Z",
       "npz_file": "tiger.npz", "npz_sha256": "<sha256 of the .npz bytes>", "num_vectors": 9,
       "meta": {...anything else the caller passed...}}

  (:func:`load_policy` also accepts a header at ``PATH + ".json"``.)

Both files are written atomically (temporary file in the same directory, then rename), so
a crash never leaves a half-written policy. :func:`load_policy` checks the header against
the arrays (their SHA-256) and, given a model, the model's
:meth:`~pearl_pomdp.model.pomdp.Pomdp.fingerprint`; every problem is a
:class:`~pearl_pomdp.errors.PolicyError` naming the file and what is wrong.
"""
from __future__ import annotations

import datetime as _dt
import hashlib
import io
import json
import math
from pathlib import Path
from typing import Any, Dict, Optional, Union

import numpy as np

from pearl_pomdp.atomic import atomic_write
from pearl_pomdp.errors import PolicyError
from pearl_pomdp.jsonable import numpy_to_json
from pearl_pomdp.model.pomdp import Pomdp
from pearl_pomdp.policies.most_likely_state import MostLikelyStatePolicy
from pearl_pomdp.solution import AlphaVectorPolicy

__all__ = ["save_policy", "load_policy", "read_policy_header", "header_path", "FORMAT", "FORMAT_VERSION"]

FORMAT = "pearl-policy"
FORMAT_VERSION = 1
KIND_ALPHA = "alpha_vectors"
KIND_MLS = "most_likely_state"

PathLike = Union[str, Path]


def header_path(path: PathLike) -> Path:
    """Where the JSON header of the policy at ``path`` is written: ``path`` with suffix ``.json``."""
    path = Path(path)
    if path.suffix.lower() == ".json":
        raise PolicyError(f"{path}: a policy path must not end in .json (that name is used by its header)")
    return path.with_suffix(".json")


def _kind_of(policy) -> str:
    if isinstance(policy, AlphaVectorPolicy):
        return KIND_ALPHA
    if isinstance(policy, MostLikelyStatePolicy):
        return KIND_MLS
    raise PolicyError(
        f"cannot save a {type(policy).__name__}: supported are AlphaVectorPolicy (alphas, actions) "
        "and MostLikelyStatePolicy (state_actions)"
    )


def _json_number(value: Any) -> Any:
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def save_policy(path: PathLike, policy, model: Pomdp, meta: Optional[dict] = None) -> Path:
    """Save ``policy`` (solved for ``model``) to ``path`` (.npz) and its JSON header.

    Args:
        path: the ``.npz`` file to write (the name is used as given; the header goes to
            :func:`header_path`).
        policy: an ``AlphaVectorPolicy`` (``alphas [K, S]``, ``actions [K]``) or a
            ``MostLikelyStatePolicy`` (``state_actions [S]``).
        model: the model it was solved for (its fingerprint, name and sizes go in the header).
        meta: ``method``, ``value_at_start``, ``upper_bound``, ``seconds`` (solve time) and any
            other JSON-serialisable facts (kept under ``"meta"``).

    Returns:
        The path of the ``.npz`` file.

    Raises:
        PolicyError: the policy does not fit the model or cannot be written.
    """
    path = Path(path)
    hpath = header_path(path)
    meta = dict(meta or {})
    kind = _kind_of(policy)
    S, A = model.num_states, model.num_actions
    if kind == KIND_ALPHA:
        alphas = np.atleast_2d(np.asarray(policy.alphas, dtype=float))
        actions = np.asarray(policy.actions, dtype=np.int64).ravel()
        if alphas.shape[1] != S or actions.shape[0] != alphas.shape[0]:
            raise PolicyError(f"{path}: α-vectors have shape {alphas.shape} with {actions.shape[0]} actions; "
                              f"model '{model.name}' has {S} states")
        arrays = {"alphas": alphas, "actions": actions}
        count = {"num_vectors": int(alphas.shape[0])}
    else:
        state_actions = np.asarray(policy.state_actions, dtype=np.int64).ravel()
        if state_actions.shape != (S,):
            raise PolicyError(f"{path}: state_actions has shape {state_actions.shape}; model '{model.name}' has {S} states")
        arrays = {"state_actions": state_actions}
        actions = state_actions
        count = {}
    if actions.size and (actions.min() < 0 or actions.max() >= A):
        raise PolicyError(f"{path}: action index {int(actions.max())} out of range for model '{model.name}' with {A} actions")

    buffer = io.BytesIO()
    named: Dict[str, Any] = dict(arrays)   # name → array (numpy's stub would also match allow_pickle)
    np.savez(buffer, **named)
    data = buffer.getvalue()
    header = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "kind": kind,
        "model_name": model.name,
        "model_fingerprint": model.fingerprint(),
        "states": S,
        "actions": A,
        "observations": model.num_observations,
        "action_names": list(model.actions),
        "method": meta.pop("method", None),
        "value_at_start": _json_number(meta.pop("value_at_start", None)),
        "upper_bound": _json_number(meta.pop("upper_bound", None)),
        "solve_seconds": _json_number(meta.pop("seconds", meta.pop("solve_seconds", None))),
        "created": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "npz_file": path.name,
        "npz_sha256": hashlib.sha256(data).hexdigest(),
        **count,
        "meta": meta,
    }
    try:
        text = json.dumps(header, indent=2, default=numpy_to_json) + "\n"
    except TypeError as err:
        raise PolicyError(f"{hpath}: meta is not JSON-serialisable: {err}") from None
    try:
        atomic_write(path, data)
        atomic_write(hpath, text)
    except OSError as err:
        raise PolicyError(f"{err.filename or path}: cannot write policy: {err.strerror or err}") from None
    return path


def read_policy_header(path: PathLike) -> dict:
    """The JSON header of the policy at ``path`` (validated), or :class:`PolicyError` naming the file."""
    path = Path(path)
    candidates = [header_path(path), Path(str(path) + ".json")]
    hpath = next((c for c in candidates if c.is_file()), None)
    if hpath is None:
        raise PolicyError(f"{path}: policy header {candidates[0]} not found (a policy is the .npz file plus "
                          "its JSON header, as written by `pearl solve --out`)")
    try:
        header = json.loads(hpath.read_text())
    except json.JSONDecodeError as err:
        raise PolicyError(f"{hpath}:{err.lineno}: policy header is not valid JSON: {err.msg}") from None
    except (OSError, UnicodeDecodeError) as err:
        raise PolicyError(f"{hpath}: cannot read policy header: {err}") from None
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        raise PolicyError(f"{hpath}: not a Pearl policy header (expected \"format\": \"{FORMAT}\")")
    version = header.get("format_version")
    if version != FORMAT_VERSION:
        raise PolicyError(f"{hpath}: format_version {version!r} is not supported (this version reads {FORMAT_VERSION})")
    for key, typ in (("kind", str), ("model_fingerprint", str), ("states", int), ("actions", int),
                     ("observations", int), ("npz_sha256", str)):
        if not isinstance(header.get(key), typ):
            raise PolicyError(f"{hpath}: field {key!r} is missing or not a {typ.__name__}")
    if header["kind"] not in (KIND_ALPHA, KIND_MLS):
        raise PolicyError(f"{hpath}: kind {header['kind']!r} is unknown (expected {KIND_ALPHA!r} or {KIND_MLS!r})")
    header["_header_path"] = str(hpath)
    return header


def load_policy(path: PathLike, model: Optional[Pomdp] = None):
    """Load a policy written by :func:`save_policy`.

    Args:
        path: the ``.npz`` file.
        model: when given, the policy must have been solved for this exact model (same
            :meth:`~pearl_pomdp.model.pomdp.Pomdp.fingerprint`).

    Returns:
        An ``AlphaVectorPolicy`` or a ``MostLikelyStatePolicy``; its header dict is
        attached as ``policy.header``.

    Raises:
        PolicyError: a file is missing, corrupt, inconsistent, or the model does not match
            (the message names the file and what differs).
    """
    path = Path(path)
    if not path.is_file():
        raise PolicyError(f"{path}: policy file not found")
    header = read_policy_header(path)
    hpath = header["_header_path"]
    if model is not None:
        fp = model.fingerprint()
        if header["model_fingerprint"] != fp:
            raise PolicyError(
                f"{path}: policy was solved for model '{header.get('model_name')}' "
                f"(fingerprint {header['model_fingerprint'][:12]}…, {header['states']} states, "
                f"{header['actions']} actions, {header['observations']} observations), this model is "
                f"'{model.name}' ({fp[:12]}…, {model.num_states} states, {model.num_actions} actions, "
                f"{model.num_observations} observations)"
            )
    try:
        data = path.read_bytes()
    except OSError as err:
        raise PolicyError(f"{path}: cannot read policy: {err.strerror or err}") from None
    if hashlib.sha256(data).hexdigest() != header["npz_sha256"]:
        raise PolicyError(f"{path}: the arrays do not match the header {hpath} (npz_sha256 differs: "
                          "the .npz was replaced or corrupted after saving)")
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
    except Exception as err:  # zipfile/numpy raise many types on corrupt input
        raise PolicyError(f"{path}: not a readable .npz policy ({type(err).__name__}: {err})") from None

    S, A = header["states"], header["actions"]

    def need(name, ndim, dtype_kind):
        arr = arrays.get(name)
        if arr is None:
            raise PolicyError(f"{path}: array {name!r} is missing (has: {', '.join(sorted(arrays)) or 'none'})")
        if arr.ndim != ndim or arr.dtype.kind not in dtype_kind:
            raise PolicyError(f"{path}: array {name!r} has shape {arr.shape} and dtype {arr.dtype}, "
                              f"expected {ndim} dimension(s) of kind {dtype_kind!r}")
        return arr

    def check_actions(name, acts):
        if acts.size and (acts.min() < 0 or acts.max() >= A):
            raise PolicyError(f"{path}: {name!r} has action index {int(acts.max() if acts.max() >= A else acts.min())}, "
                              f"outside 0..{A - 1}")

    if header["kind"] == KIND_ALPHA:
        alphas = need("alphas", 2, "f")
        actions = need("actions", 1, "iu")
        if alphas.shape[1] != S or alphas.shape[0] != actions.shape[0]:
            raise PolicyError(f"{path}: alphas {alphas.shape} and actions {actions.shape} do not fit {S} states")
        if not np.isfinite(alphas).all():
            raise PolicyError(f"{path}: alphas has a non-finite entry")
        check_actions("actions", actions)
        policy: Union[AlphaVectorPolicy, MostLikelyStatePolicy] = AlphaVectorPolicy(alphas, actions)
    else:
        state_actions = need("state_actions", 1, "iu")
        if state_actions.shape != (S,):
            raise PolicyError(f"{path}: state_actions has shape {state_actions.shape}, expected ({S},)")
        check_actions("state_actions", state_actions)
        policy = MostLikelyStatePolicy(state_actions.astype(np.int64))
    try:
        setattr(policy, "header", {k: v for k, v in header.items() if not k.startswith("_")})
    except AttributeError:  # a class with __slots__: the header is still available via read_policy_header
        pass
    return policy
