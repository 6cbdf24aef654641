"""Shutdown under an input flood (issue 14 acceptance), printed as ONE JSON object.

Every node of the package as its own process, all at once, with a flood publisher on every
topic they subscribe to; once all are ready, SIGINT (or SIGTERM) goes to all of them, and
each exit is timed. ``--repetitions`` (default 20) per signal. The acceptance: every exit
code 0, every exit within 2 s, no traceback. The same harness runs 2 repetitions per signal
in ``test/test_shutdown.py``.

    .venv/bin/python bench/shutdown.py [--repetitions 20] [--rate 500]

Uses the planned policy committed with the bags (``bags/pearl``), so no node plans.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "test"))
sys.path.insert(0, str(REPO))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repetitions", type=int, default=20, help="repetitions per signal (default 20)")
    parser.add_argument("--rate", type=float, default=500.0, help="flood messages/s per topic (default 500)")
    args = parser.parse_args()

    from ros_helpers import configure_test_process
    from test_shutdown import EXIT_WITHIN, failures, pearl_nodes, shutdown_trials

    def progress(sig, rep):
        if sys.stderr.isatty():
            print(f"\r{sig} {rep + 1}/{args.repetitions}", end="", file=sys.stderr, flush=True)

    with tempfile.TemporaryDirectory() as tmp:
        configure_test_process(Path(tmp))
        nodes = pearl_nodes(REPO / "bags" / "pearl" / "domain.yaml", REPO / "bags" / "pearl" / "policy")
        t0 = time.monotonic()
        results = shutdown_trials(Path(tmp), nodes, ("SIGINT", "SIGTERM"), args.repetitions, rate=args.rate,
                                  progress=progress)
        wall = time.monotonic() - t0
    if sys.stderr.isatty():
        print(file=sys.stderr)
    per = {}
    for r in results:
        key = f"{r['node']} {r['signal']}"
        per.setdefault(key, []).append(r)
    summary = {}
    for key, rs in sorted(per.items()):
        secs = [r["seconds"] for r in rs if r["seconds"] is not None]
        summary[key] = {"trials": len(rs), "exit_0": sum(r["code"] == 0 for r in rs),
                        f"within_{EXIT_WITHIN:g}s": sum(r["seconds"] is not None and r["seconds"] < EXIT_WITHIN
                                                       for r in rs),
                        "median_s": round(statistics.median(secs), 3) if secs else None,
                        "max_s": max(secs) if secs else None}
    bad = failures(results)
    print(json.dumps({"repetitions_per_signal": args.repetitions, "flood_rate_per_topic": args.rate,
                      "nodes": [n.name for n in nodes], "trials": len(results), "failures": len(bad),
                      "failed": bad[:10], "per_node_and_signal": summary, "wall_s": round(wall, 1)}))
    return 0 if not bad else 1


if __name__ == "__main__":
    sys.exit(main())
