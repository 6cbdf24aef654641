"""Write a factored domain's flat model for other solvers (pomdp-solve, SARSOP).

    pearl export DOMAIN [--format pomdp|pomdpx] [--out FILE] [--json]

DOMAIN is a factored domain ``.yaml`` (a ``.pomdp`` file is accepted too and re-written).
The flat model is written in Cassandra's ``.pomdp`` format (default) or SARSOP's PomdpX,
to FILE (atomically) or, without ``--out``, to stdout. State names are the feature
assignments (``RobotLocation=home,UserLocation=room,…``) where the format allows them;
the writers rewrite names that do not fit, keeping the order. With ``--out``, ``--json``
prints one object: ``domain``, ``out``, ``format``, ``states``, ``actions``,
``observations``, ``fingerprint``, ``seconds``.

Examples (the flat Pearl model for SARSOP; the Table 4 model on stdout)::

    pearl export config/pearl.domain.yaml --format pomdpx --out pearl.pomdpx
    pearl export config/table4.domain.yaml | head -5
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from pearl_pomdp.errors import PearlError

COMMAND = "export"
HELP = "write a domain's flat model as .pomdp or PomdpX (for pomdp-solve / SARSOP)"

FORMATS = ("pomdp", "pomdpx")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("domain", metavar="DOMAIN", help="a factored domain .yaml (or a .pomdp)")
    parser.add_argument("--format", choices=FORMATS, default=None,
                        help="output format (default: from --out's extension, else pomdp)")
    parser.add_argument("--out", metavar="FILE", default=None, help="output file (default: stdout)")
    parser.add_argument("--json", action="store_true", help="with --out: print one JSON object on stdout")


def run(args: argparse.Namespace) -> int:
    from pearl_pomdp.model import load_model

    fmt = args.format
    out = Path(args.out) if args.out else None
    if fmt is None:
        fmt = "pomdpx" if out is not None and out.suffix.lower() == ".pomdpx" else "pomdp"
    if out is not None and out.suffix.lower() in (".pomdp", ".pomdpx") and out.suffix.lower()[1:] != fmt:
        raise PearlError(f"{out}: the extension says {out.suffix[1:]} but --format is {fmt}")
    if args.json and out is None:
        raise PearlError("--json needs --out (without it the model itself goes to stdout)")
    src = Path(args.domain)
    if out is not None and out.resolve() == src.resolve():
        raise PearlError(f"{out}: output is the input file")
    from pearl_pomdp.cli._inputs import require_file

    require_file(src, "domain file (.yaml, or a .pomdp)")
    t0 = time.perf_counter()
    model = load_model(src)
    if fmt == "pomdp":
        from pearl_pomdp.model.pomdp_writer import format_pomdp as render, write_pomdp as write
    else:
        from pearl_pomdp.model.pomdpx import format_pomdpx as render, write_pomdpx as write
    if out is None:
        sys.stdout.write(render(model))
        sys.stdout.flush()
        return 0
    write(model, out)
    seconds = time.perf_counter() - t0
    if args.json:
        from pearl_pomdp.cli import print_json

        print_json({
            "domain": str(src), "out": str(out), "format": fmt,
            "states": model.num_states, "actions": model.num_actions, "observations": model.num_observations,
            "fingerprint": model.fingerprint(), "seconds": round(seconds, 4),
        })
    else:
        print(f"{src} -> {out} ({fmt}: {model.num_states} states, {model.num_actions} actions, "
              f"{model.num_observations} observations) in {seconds:.2f} s", file=sys.stderr)
    return 0
