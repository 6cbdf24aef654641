"""Fast DDS shared memory left by stopped nodes (``pearl_pomdp.shared_memory``; ``pearl launch`` cleans up).

* By hand, in a temporary directory: a segment whose lock file a living process holds stays; one
  whose lock nobody holds goes with its lock file; a port goes with its lock and its semaphore;
  other files stay; the living one goes once its process ends.
* With real Fast DDS: a package node stopped by SIGINT leaves its segment in ``/dev/shm`` (its DDS
  entities are left to the process's end, ``run_node``), and ``remove_dead_files`` removes exactly
  what the stopped node left, not the segment of a participant that is still running.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from pearl_pomdp.shared_memory import DEFAULT_DIRECTORY, _held_by_a_living_process, remove_dead_files
from ros_helpers import REPO, Proc, ros_env, wait_for

HOLD_LOCK = textwrap.dedent("""
    import fcntl, os, sys
    fd = os.open(sys.argv[1], os.O_RDONLY)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    print("locked", flush=True)
    sys.stdin.read()          # until the test closes our stdin
""")


def _write(path: Path, size: int, age: float = 60.0) -> None:
    path.write_bytes(b"\0" * size)
    past = path.stat().st_mtime - age
    os.utime(path, (past, past))


def test_dead_files_go_living_ones_stay_by_hand(tmp_path):
    live, dead = "fastrtps_0123456789abcdef", "fastrtps_fedcba9876543210"
    for name, size in ((live, 700), (f"{live}_el", 0), (dead, 500), (f"{dead}_el", 0), ("fastrtps_port7411", 300),
                       ("fastrtps_port7411_el", 0), ("sem.fastrtps_port7411_mutex", 32),
                       ("fastrtps_port7000", 52), ("sem.fastrtps_port7000_mutex", 32), ("unrelated_el", 0)):
        _write(tmp_path / name, size)
    holder = subprocess.Popen([sys.executable, "-c", HOLD_LOCK, str(tmp_path / f"{live}_el")], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        first = remove_dead_files(tmp_path)
        assert sorted(first.removed) == sorted([dead, f"{dead}_el", "fastrtps_port7411", "fastrtps_port7411_el",
                                                "sem.fastrtps_port7411_mutex"])
        assert first.removed_bytes == 500 + 300 + 32 and first.in_use == 1
        # A port without a lock file cannot be judged (Fast DDS's own rule): it stays, as do other files.
        assert sorted(os.listdir(tmp_path)) == sorted([live, f"{live}_el", "fastrtps_port7000",
                                                       "sem.fastrtps_port7000_mutex", "unrelated_el"])
    finally:
        holder.stdin.close()
        holder.wait(10)
    second = remove_dead_files(tmp_path)
    assert sorted(second.removed) == [live, f"{live}_el"] and second.removed_bytes == 700 and second.in_use == 0


def test_a_lock_file_younger_than_min_age_is_left(tmp_path):
    # A participant starting now creates its lock file, then locks it: unlocked in between, not dead.
    young = "fastrtps_00000000000000aa"
    _write(tmp_path / young, 100, age=0.0)
    _write(tmp_path / f"{young}_el", 0, age=0.0)
    assert remove_dead_files(tmp_path).removed == []
    assert sorted(remove_dead_files(tmp_path, min_age=0.0).removed) == [young, f"{young}_el"]


def test_a_missing_directory_is_nothing_to_clean(tmp_path):
    result = remove_dead_files(tmp_path / "absent")
    assert result.removed == [] and result.in_use == 0


def _segments() -> set:
    return {n for n in os.listdir(DEFAULT_DIRECTORY) if n.startswith("fastrtps_") and n.endswith("_el")
            and not n.startswith("fastrtps_port")}


def _segments_locked_by(pid: int) -> set:
    """The segment lock files of ``DEFAULT_DIRECTORY`` that process ``pid`` holds (``/proc/locks``).
    Other test processes (pytest-xdist workers, another run) start and stop participants meanwhile:
    a difference of two listings would count theirs too."""
    held = set()
    for line in Path("/proc/locks").read_text().splitlines():
        fields = line.split()
        # "1: FLOCK  ADVISORY  WRITE 12345 00:1b:9548 0 EOF": device (hex major:minor) and inode of the
        # locked file; a waiter's line ("1: -> FLOCK …") is not a holder.
        if len(fields) >= 6 and fields[1] == "FLOCK" and fields[4] == str(pid):
            major, minor, inode = fields[5].split(":")
            held.add((int(major, 16), int(minor, 16), int(inode)))
    owned = set()
    for name in _segments():
        try:
            info = (DEFAULT_DIRECTORY / name).stat()
        except OSError:
            continue
        if (os.major(info.st_dev), os.minor(info.st_dev), info.st_ino) in held:
            owned.add(name)
    return owned


def _date(names: set, offset: float) -> None:
    """Set the modification time of ``DEFAULT_DIRECTORY``'s ``names`` to now + ``offset`` s."""
    when = time.time() + offset
    for name in names:
        os.utime(DEFAULT_DIRECTORY / name, (when, when))


@pytest.mark.ros
@pytest.mark.skipif(not DEFAULT_DIRECTORY.is_dir(), reason="no /dev/shm: Fast DDS keeps no shared memory files here")
def test_a_node_stopped_by_sigint_leaves_its_segment_and_the_clean_up_removes_only_that(ros_context, tmp_path):
    import rclpy

    context, domain_id = ros_context
    probe = rclpy.create_node("shm_probe", context=context)      # a participant that stays alive
    try:
        living = _segments_locked_by(os.getpid())
        assert living, "this process's participant has no shared-memory segment"
        node = Proc([str(Path(sys.executable).parent / "action_executor"), "--ros-args", "--params-file",
                     str(REPO / "config" / "pearl_nodes.yaml")], ros_env(domain_id, tmp_path / "log"),
                    tmp_path / "log", "action_executor")
        try:
            # Up means its start-up is done (it says what it executes), not only its name in the graph:
            # a SIGINT in the middle of its start-up is test_shutdown's business.
            assert wait_for(lambda: "executing" in node.stdout() + node.stderr()
                            and "action_executor" in probe.get_node_names(), timeout=60), node.stderr()
            left_by_node = _segments_locked_by(node.popen.pid)
            assert left_by_node, "the node's participant has no shared-memory segment"
            # Other test processes clean /dev/shm too (a `pearl launch` ending in another xdist worker),
            # and would take the stopped node's segment before this test looks. Every clean-up leaves
            # lock files younger than a second (a participant between creating its lock file and
            # locking it): dated a minute ahead, the node's are left alone until the test dates them back.
            _date(left_by_node, +60.0)
            node.popen.send_signal(signal.SIGINT)
            assert node.wait(10) == 0, node.stderr()
        finally:
            node.stop()
        assert left_by_node <= _segments(), "the stopped node removed its segment: nothing to clean"
        assert not any(_held_by_a_living_process(DEFAULT_DIRECTORY / n) for n in left_by_node)
        _date(left_by_node, -5.0)
        result = remove_dead_files()
        assert left_by_node <= set(result.removed)
        after = _segments()
        assert not (left_by_node & after) and living <= after
        assert all(_held_by_a_living_process(DEFAULT_DIRECTORY / n) for n in living)
    finally:
        probe.destroy_node()
