"""Models: the flat :class:`Pomdp`, the ``.pomdp``/PomdpX formats and factored YAML domains."""
from __future__ import annotations

from pathlib import Path
from typing import Union

from pearl_pomdp.model.pomdp import Pomdp

__all__ = ["Pomdp", "load_model", "load_domain_or_model"]


def load_model(path: Union[str, Path]) -> Pomdp:
    """Load a flat model from a ``.pomdp`` / flat ``.pomdpx`` file or a factored domain ``.yaml``
    (compiled).

    Raises:
        pearl_pomdp.errors.SpecError: the file is invalid (the message names file and line/field).
        FileNotFoundError: no such file.
    """
    loaded = load_domain_or_model(path)
    return loaded if isinstance(loaded, Pomdp) else loaded.compile()


def load_domain_or_model(path: Union[str, Path]):
    """A factored domain (:class:`~pearl_pomdp.model.factored.FactoredDomain`) from a ``.yaml`` file,
    else the flat :class:`Pomdp` of a ``.pomdp`` / flat ``.pomdpx`` file; raises as :func:`load_model`."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(2, "no such model file", str(path))
    if path.suffix.lower() in (".yaml", ".yml"):
        from pearl_pomdp.model.domain_yaml import load_domain

        return load_domain(path)
    if path.suffix.lower() == ".pomdpx":
        from pearl_pomdp.model.pomdpx import read_pomdpx

        return read_pomdpx(path)
    from pearl_pomdp.model.pomdp_format import read_pomdp

    return read_pomdp(path)
