"""pearl_sim/workers.py: the studies' forked workers never finalize the parent's garbage (a ROS node's
finalizer in a forked child segfaulted it), and a worker that dies stops the study with an error
instead of a wait for ever."""
from __future__ import annotations

import gc
import os
import signal
import time
from pathlib import Path

import pytest

from pearl_pomdp.errors import PearlError
from pearl_sim.workers import fork_pool



class _Cycle:
    """Garbage only the cyclic collector frees; its finalizer notes the process it ran in."""

    def __init__(self, log: Path):
        self.me = self
        self.log = log

    def __del__(self):
        with open(self.log, "a") as out:
            out.write(f"{os.getpid()}\n")


def _collect_in_child(_):
    gc.collect()
    return os.getpid()


def test_the_parents_garbage_is_finalized_in_the_parent_never_in_a_forked_worker(tmp_path):
    log = tmp_path / "finalized"
    was_enabled = gc.isenabled()
    gc.disable()          # the cycle stays uncollected until someone collects
    try:
        _Cycle(log)
        with fork_pool(2) as pool:
            children = set(pool.map(_collect_in_child, range(8)))
        assert children and os.getpid() not in children
    finally:
        if was_enabled:
            gc.enable()
    assert log.read_text().split() == [str(os.getpid())]     # once, in the parent, before the fork
    assert gc.get_freeze_count() == 0                           # the parent's objects are collectable again


def _die_on_three(i):
    if i == 3:
        os.kill(os.getpid(), signal.SIGKILL)     # as the segfault or the out-of-memory killer would
    return i


def test_a_worker_that_dies_stops_the_study_with_an_error_not_a_wait():
    start = time.monotonic()
    with pytest.raises(PearlError, match="a study worker process died before its tasks were done"):
        with fork_pool(2) as pool:
            list(pool.map(_die_on_three, range(8)))
    assert time.monotonic() - start < 30.0
