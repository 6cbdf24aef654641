"""Reliability figures of issue 7, printed as ONE JSON object.

* fuzz: inputs fuzzed over every reader (bench/fuzz.py), crashes (must be 0).
* flood: the belief tracker as its own process, a publisher process sending mixed valid/invalid
  strings at --rate msg/s (target 10,000) for --seconds s (target 10): rate achieved, messages
  the tracker took, lost_inputs (DDS dropped them, counted), unaccounted (must be 0), beliefs
  published and whether all were valid (finite, ≥ 0, sum 1), tracker RSS growth.
* sigkill: --trials (≥ 50) bag writers SIGKILLed at random moments: bags readable and
  messages missing among those write() returned for (must be 0: a missing, altered or
  invented message fails the trial and is listed in `failures`).

    .venv/bin/python bench/reliability.py [--fuzz 2000] [--rate 10000] [--seconds 10] [--trials 50]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "test"))
sys.path.insert(0, str(REPO / "bench"))
sys.path.insert(0, str(REPO))


def flood(rate: float, seconds: float) -> dict:
    from test_node_robustness import FLOOD, Graph, _valid, accounted, flood_and_account, rss_kb

    from pearl_pomdp.nodes import conversions as cv

    with tempfile.TemporaryDirectory() as tmpdir:
        g = Graph(Path(tmpdir))
        try:
            tracker = g.tracker()
            if not g.wait(lambda: g.beliefs and g.counters(), 90):
                return {"error": "tracker did not start", "stderr": tracker.stderr()[-1000:]}
            base_c = dict(g.counters())
            base = accounted(base_c)
            rss0 = rss_kb(tracker.popen.pid)
            n_beliefs = len(g.beliefs)
            proc = g.start("flood", [sys.executable, "-c", FLOOD, str(seconds), str(rate), "11"])
            sent, got, c = flood_and_account(g, proc, base, timeout=seconds + 90)
            beliefs = [cv.msg_to_belief(m) for m in g.beliefs[n_beliefs:]]
            taken = got - (int(c["lost_inputs"]) - int(base_c.get("lost_inputs", 0)))
            return {"target_rate": rate, "target_seconds": seconds, "sent": sent["total"],
                    "achieved_rate": round(sent["rate"], 1), "seconds": round(sent["seconds"], 2),
                    "taken_by_tracker": taken, "lost_inputs_counted": int(c["lost_inputs"]) - int(base_c.get("lost_inputs", 0)),
                    "unaccounted": sent["total"] - got, "beliefs_published": len(beliefs),
                    "beliefs_valid": all(_valid(b) for b in beliefs), "tracker_alive": tracker.returncode is None,
                    "tracker_rss_growth_kb": rss_kb(tracker.popen.pid) - rss0, "counters": c}
        finally:
            g.close()


def sigkill(trials: int, seed: int = 0) -> dict:
    from test_crash_safe_writes import sigkill_trial

    rng = np.random.default_rng(seed)
    readable, reported, read, failures = 0, 0, 0, []
    with tempfile.TemporaryDirectory() as tmpdir:
        for t in range(trials):
            d = Path(tmpdir) / f"t{t}"
            d.mkdir()
            try:
                r = sigkill_trial(d, float(rng.uniform(0.02, 0.5)))
                readable += 1
                reported += r["reported"]
                read += r["read"]
            except Exception as err:  # noqa: BLE001 - reported, not hidden
                failures.append(repr(err)[:200])
    return {"trials": trials, "bags_readable": readable, "messages_reported_written": reported,
            "messages_read": read, "failures": failures}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fuzz", type=int, default=2000)
    ap.add_argument("--rate", type=float, default=10000)
    ap.add_argument("--seconds", type=float, default=10)
    ap.add_argument("--trials", type=int, default=50)
    args = ap.parse_args()
    from fuzz import run as fuzz_run

    load0 = os.getloadavg()
    t0 = time.perf_counter()
    f = fuzz_run(args.fuzz, 0)
    out = {"load_average_start": [round(x, 2) for x in load0], "cpus": os.cpu_count(),
           "fuzz": {"inputs": f["inputs"], "crashes": f["crashes"], "crash_examples": f["crash_examples"]}}
    out["sigkill"] = sigkill(args.trials)
    out["flood"] = flood(args.rate, args.seconds)
    out["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    out["seconds"] = round(time.perf_counter() - t0, 1)
    ok = (f["crashes"] == 0 and out["flood"].get("unaccounted") == 0 and out["flood"].get("beliefs_valid")
          and out["sigkill"]["bags_readable"] == args.trials and not out["sigkill"]["failures"])
    out["ok"] = bool(ok)
    print(json.dumps(out))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
