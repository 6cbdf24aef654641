"""`--jobs` speed-up of the study and its determinism (issue 12: `--jobs 2` gives the numbers of
`--jobs 1` in less wall time).

Runs the same grid (cheap policies — behaviour tree, QMDP, most-likely-state — on the paper's
six residents × three tasks, noise 0 and 0.6, ``--seeds`` seeds) with ``jobs=1`` and ``jobs=2``
and compares every episode's scores.

    .venv/bin/python bench/study_jobs.py [--seeds 1]

Prints one JSON object: wall seconds per job count, the speed-up, whether the episodes are
identical, and the 1-minute load average (the machine is shared: read the speed-up with it).
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=1)
    args = parser.parse_args()
    logging.getLogger("pearl_pomdp").setLevel(logging.ERROR)
    from pearl_sim.nursing_home import study
    from pearl_sim.nursing_home.experiment import build_agents
    from pearl_sim.nursing_home.residents import paper_residents, resident_scenarios, study_template
    from pearl_sim.nursing_home.scenario import default_domain

    path = REPO / "config" / "scenarios" / "study.yaml"
    domain = default_domain()
    agents = build_agents(domain, None, policies=["behaviour_tree", "qmdp", "most_likely_state"])
    cases = resident_scenarios(study_template(path), paper_residents(path))
    grid = study.cells(len(cases), [0.0, 0.6], args.seeds)
    walls, rows = {}, {}
    for jobs in (1, 2):
        t0 = time.perf_counter()
        rows[jobs] = [e.row() for e in study.run_cells(domain, agents, cases, grid, jobs=jobs)]
        walls[jobs] = round(time.perf_counter() - t0, 2)
    print(json.dumps({"episodes": len(rows[1]), "wall_seconds": {str(k): v for k, v in walls.items()},
                      "speedup_jobs2": round(walls[1] / walls[2], 2), "identical": rows[1] == rows[2],
                      "cpu_count": os.cpu_count(), "load_average_1min": round(os.getloadavg()[0], 2)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
