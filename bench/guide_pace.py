"""Guidance with and without walking-pace adaptation (issue 14), printed as ONE JSON object.

For each resident class — the slow residents of ``config/scenarios/study.yaml`` (5, 10, 20,
35 cm/s, with rests) and two faster ones (0.5 and 1 m/s) — ``--seeds`` guidances of 25 m
(the follower model of ``test/test_guide_pace.py``: she cannot pass the robot, rests now and
then, gives up 15 m behind) at fixed pace (cruise 0.6 m/s, as Pearl in the paper) and with
``pearl_pomdp.guide_pace.GuidePace``: completed %, given up %, reported lost, mean duration,
and the robot's mean speed over cruise (1 m/s: the acceptance margin is 2 %).

    .venv/bin/python bench/guide_pace.py [--seeds 200]
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "test"))
sys.path.insert(0, str(REPO))

RESIDENTS = [(0.05, 0.03), (0.1, 0.03), (0.2, 0.02), (0.35, 0.01), (0.5, 0.0), (1.0, 0.0)]
CRUISE, LENGTH = 0.6, 25.0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=200, help="guidances per resident class and mode")
    args = parser.parse_args()
    from test_guide_pace import FAST_MARGIN, guide_one

    t0 = time.monotonic()
    table = []
    for speed, rests in RESIDENTS:
        row = {"walking_speed": speed, "rests_per_s": rests}
        for mode, adapt in (("fixed", False), ("guide_pace", True)):
            runs = [guide_one(speed, rests, seed=s, adapt=adapt, cruise=CRUISE, length=LENGTH) for s in range(args.seeds)]
            done = [r for r in runs if r["completed"]]
            robot = [r["robot_seconds"] for r in runs if r["robot_seconds"]]
            row[mode] = {"completed_pct": round(100.0 * len(done) / len(runs), 1),
                         "gave_up_pct": round(100.0 * sum(r["gave_up"] for r in runs) / len(runs), 1),
                         "reported_lost": sum(r["lost_reported"] for r in runs),
                         "mean_seconds_completed": round(statistics.mean(r["seconds"] for r in done), 1) if done else None,
                         "robot_speed_over_cruise": round(statistics.mean(LENGTH / s for s in robot) / CRUISE, 4)
                         if robot else None,
                         "mean_stops": round(statistics.mean(r["stops"] for r in runs), 2)}
        table.append(row)
    slow = [r for r in table if r["walking_speed"] <= 0.35]
    fast = next(r for r in table if r["walking_speed"] == 1.0)
    print(json.dumps({"seeds": args.seeds, "length_m": LENGTH, "cruise_m_s": CRUISE, "residents": table,
                      "slow_completed_pct_guide_pace": round(statistics.mean(r["guide_pace"]["completed_pct"]
                                                                             for r in slow), 1),
                      "slow_completed_pct_fixed": round(statistics.mean(r["fixed"]["completed_pct"] for r in slow), 1),
                      "fast_speed_over_cruise": fast["guide_pace"]["robot_speed_over_cruise"],
                      "fast_margin": FAST_MARGIN,
                      "fast_within_margin": fast["guide_pace"]["robot_speed_over_cruise"] >= 1 - FAST_MARGIN,
                      "wall_s": round(time.monotonic() - t0, 1)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
