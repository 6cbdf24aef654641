"""The one-loop parity check of test/test_one_loop.py on more seeds (one JSON object on stdout).

The study's fast path (the core Executive on the world's clock) and the real nodes over DDS under
/clock run the same seeded scenarios; per scenario: seeds run, whether every action list was
identical, the largest belief difference, and how many drives and timeout-closed steps the
episodes exercised. The suite runs 6 seeds per scenario; this runs ``--seeds`` (default 20).

    .venv/bin/python bench/one_loop.py [--seeds 20] [--scenarios figure4,table4_dialog,info_request]
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

from ros_helpers import DOMAIN, HIERARCHY  # noqa: E402
from test_one_loop import SCENARIOS, fast, on_graph  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--scenarios", default=",".join(SCENARIOS))
    args = ap.parse_args()

    from pearl_pomdp.hierarchy import load_hierarchy, plan
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.nursing_home.scenario import load_scenarios

    domain = load_domain(DOMAIN)
    model = domain.compile()
    with tempfile.TemporaryDirectory() as tmp:
        decider = plan(domain, load_hierarchy(HIERARCHY, domain))   # start-up, not timed below
        out = {"benchmark": "one_loop", "seeds": args.seeds, "scenarios": {}}
        t0 = time.perf_counter()
        for name in [s for s in args.scenarios.split(",") if s]:
            (scenario,) = load_scenarios(REPO / "config" / "scenarios" / f"{name}.yaml")
            same, worst, drives, silences = True, 0.0, 0, 0
            for seed in range(args.seeds):
                actions, beliefs, timeouts = fast(domain, model, decider, scenario, seed)
                ros_actions, ros_beliefs = on_graph(domain, model, decider, scenario, seed, Path(tmp))
                same = same and ros_actions == actions and len(ros_beliefs) == len(beliefs)
                if len(ros_beliefs) == len(beliefs):
                    worst = max([worst] + [float(np.max(np.abs(a - b))) for a, b in zip(ros_beliefs, beliefs)])
                drives += sum(a in ("GotoPatientRoom", "GuideToPhysio", "GoHome") for a in actions)
                silences += timeouts
            out["scenarios"][name] = {"identical_actions": same, "max_belief_difference": worst,
                                      "drives": drives, "timeout_steps": silences}
        out["seconds"] = round(time.perf_counter() - t0, 1)
        out["load_average_1min"] = round(os.getloadavg()[0], 2)
    print(json.dumps(out))
    return 0 if all(s["identical_actions"] and s["max_belief_difference"] <= 1e-12
                    for s in out["scenarios"].values()) else 1


if __name__ == "__main__":
    sys.exit(main())
