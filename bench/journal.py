"""What a journal write costs the tracker, printed as ONE JSON object (docs/reliability.md, "Crashes").

The tracker journals a closed step before it publishes the step's belief, so the write (JSON,
the belief as base64 float64, atomic replace) adds to every step's latency. Measured for Pearl's
576 states and the ward's 233,280, on the file system of ``--dir`` (default: a temporary
directory), in each ``journal_sync`` mode (:data:`pearl_pomdp.journal.SYNC_MODES`): ``fsync``
(the file and its directory fsynced before the write returns), ``background`` (the caller's part;
the fsync thread's is not in it) and ``none``. ``flush_ms``: background only, the wait at the end
for the last write's fsync. ``update_*``: a step's opening, which keeps the belief and goes to the
journal's small update file.

    .venv/bin/python bench/journal.py [--writes 50] [--dir DIR]
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

SIZES = {"pearl": 576, "ward": 233_280}


def measure(states: int, writes: int, directory: Path, sync: str) -> dict:
    from pearl_pomdp.journal import Journal, decode_array, encode_array, flush_journals, update_path

    belief = np.random.default_rng(0).dirichlet(np.ones(states))
    journal = Journal(directory / f"tracker_{states}_{sync}.json", "belief_tracker", "bench", "sha256:0", sync=sync)
    seconds = []
    for step in range(writes):
        start = time.perf_counter()
        journal.write({"belief": encode_array(belief), "step": step})
        seconds.append(time.perf_counter() - start)
    start = time.perf_counter()
    flush_journals(timeout=10.0)
    flush = time.perf_counter() - start
    start = time.perf_counter()
    found = journal.load()
    load = time.perf_counter() - start
    assert found.state is not None and np.array_equal(decode_array(found.state["belief"]), belief)
    ms = np.array(seconds) * 1e3
    # A step's opening: the same encoded belief, new small fields (the update file: pearl_pomdp/journal.py).
    encoded, updates = encode_array(belief), []
    journal.write({"belief": encoded, "step": writes, "open_action": None})
    for step in range(writes):
        start = time.perf_counter()
        journal.write({"belief": encoded, "step": writes, "open_action": f"Action{step}"})
        updates.append(time.perf_counter() - start)
    flush_journals(timeout=10.0)
    assert journal.updates == writes and journal.load().state["open_action"] == f"Action{writes - 1}"
    up = np.array(updates) * 1e3
    return {"states": states, "bytes": journal.path.stat().st_size, "write_p50_ms": round(float(np.median(ms)), 3),
            "write_p99_ms": round(float(np.percentile(ms, 99)), 3), "load_ms": round(load * 1e3, 3),
            **({"flush_ms": round(flush * 1e3, 3)} if sync == "background" else {}),
            "update_bytes": update_path(journal.path).stat().st_size,
            "update_p50_ms": round(float(np.median(up)), 3), "update_p99_ms": round(float(np.percentile(up, 99)), 3)}


def main() -> int:
    from pearl_pomdp.journal import SYNC_MODES

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--writes", type=int, default=50)
    ap.add_argument("--dir", type=Path, default=None, help="where to write (default: a temporary directory)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        directory = args.dir or Path(tmp)
        out = {name: {sync: measure(states, args.writes, directory, sync) for sync in SYNC_MODES}
               for name, states in SIZES.items()}
    print(json.dumps({"writes": args.writes, **out}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
