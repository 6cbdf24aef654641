"""Convert a model between Cassandra's .pomdp and SARSOP's PomdpX, by file extension.

    pearl convert MODEL OUT [--json]

MODEL is a ``.pomdp``, a flat ``.pomdpx`` or a factored domain ``.yaml`` (compiled to its flat
model); OUT ends in ``.pomdp`` or ``.pomdpx``. Floats are written losslessly, so reading OUT gives
the identical model (same fingerprint) unless names had to be rewritten to fit the format.
The file is written atomically. ``--json`` prints one object: ``model``, ``out``, ``format``,
``states``, ``actions``, ``observations``, ``fingerprint``, ``seconds``.

Examples:
  pearl convert config/table4.domain.yaml table4.pomdpx
  pearl convert table4.pomdpx table4.pomdp --json
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from pearl_pomdp.errors import PearlError

COMMAND = "convert"
HELP = "convert a model between .pomdp and .pomdpx (by extension)"

_WRITERS = (".pomdp", ".pomdpx")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("model", metavar="MODEL", help="input: .pomdp, .pomdpx or a domain .yaml")
    parser.add_argument("out", metavar="OUT", help="output: .pomdp or .pomdpx")
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")


def run(args: argparse.Namespace) -> int:
    from pearl_pomdp.model import load_model

    out = Path(args.out)
    suffix = out.suffix.lower()
    if suffix not in _WRITERS:
        raise PearlError(f"{out}: unknown output format {out.suffix or '(no extension)'!r}; use .pomdp or .pomdpx")
    src = Path(args.model)
    if src.resolve() == out.resolve():
        raise PearlError(f"{out}: output is the input file")
    from pearl_pomdp.cli._inputs import require_file

    require_file(src, "model file (.pomdp, .pomdpx or domain .yaml)")
    t0 = time.perf_counter()
    model = load_model(src)
    if suffix == ".pomdp":
        from pearl_pomdp.model.pomdp_writer import write_pomdp as write
    else:
        from pearl_pomdp.model.pomdpx import write_pomdpx as write
    write(model, out)
    seconds = time.perf_counter() - t0
    if args.json:
        from pearl_pomdp.cli import print_json

        print_json({
            "model": str(src), "out": str(out), "format": suffix[1:],
            "states": model.num_states, "actions": model.num_actions, "observations": model.num_observations,
            "fingerprint": model.fingerprint(), "seconds": round(seconds, 4),
        })
    else:
        print(f"{src} -> {out} ({model.num_states} states, {model.num_actions} actions, "
              f"{model.num_observations} observations) in {seconds:.2f} s", file=sys.stderr)
    return 0
