"""The shared-memory files of Fast DDS participants that are gone (no ROS import: files and locks only).

Fast DDS (ROS 2 Jazzy's default middleware) gives each participant a shared-memory segment,
``/dev/shm/fastrtps_<16 hex digits>`` (512 KB by default; what a profile's ``segment_size`` says
otherwise), and each listening port a file ``fastrtps_port<N>`` with a POSIX semaphore
``sem.fastrtps_port<N>_mutex``. Beside each lives a lock file (``…_el``, or ``…_sl`` for a shared
port) that the owning process holds with ``flock`` for as long as it uses the file: the kernel
drops the lock when the process ends, however it ends.

A participant that is destroyed removes its files. A node stopped by a signal is not (its DDS
entities are left to the process's end: :func:`pearl_pomdp.nodes.common.run_node` says why), so
every stop leaves its segment behind: ~0.5 MB of memory in ``/dev/shm`` per node and stop, which
on a robot restarted for months, or in a container's 64 MB ``/dev/shm``, adds up.
:func:`remove_dead_files` removes what belongs to no living process, by the rule of Fast DDS's own
``fastdds shm clean``: a lock file that can be locked has no owner, so it and the files it guards
go. ``pearl launch`` calls it once its nodes have exited.
"""
from __future__ import annotations

import fcntl
import os
import re
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import List

__all__ = ["DEFAULT_DIRECTORY", "Cleanup", "remove_dead_files"]

#: Where Fast DDS keeps its shared memory on Linux.
DEFAULT_DIRECTORY = Path("/dev/shm")

_SEGMENT_LOCK = re.compile(r"^fastrtps_[0-9a-z]{16}_(el|sl)$")
_PORT_LOCK = re.compile(r"^fastrtps_port\d{1,5}_(el|sl)$")


@dataclass
class Cleanup:
    """What :func:`remove_dead_files` found: the files removed, and how many lock files are held."""

    removed: List[str] = field(default_factory=list)
    removed_bytes: int = 0
    in_use: int = 0


def _held_by_a_living_process(lock_file: Path) -> bool:
    """Whether some process holds ``lock_file``'s ``flock`` (a file that vanished: no)."""
    try:
        fd = os.open(lock_file, os.O_RDONLY)      # never creates: the owner may just have removed it
    except FileNotFoundError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)                               # (closing drops our lock)
    return False


def remove_dead_files(directory: Path = DEFAULT_DIRECTORY, min_age: float = 1.0) -> Cleanup:
    """Remove the Fast DDS segment and port files of ``directory`` whose owners have all ended.

    Only files of this user are touched; a lock file that some process holds keeps its files, and so
    does one younger than ``min_age`` seconds (a participant starting now creates its lock file and
    then locks it: in between it is unlocked, not dead); a file that cannot be removed is left (no
    error). Returns what was removed.
    """
    result = Cleanup()
    try:
        names = os.listdir(directory)
    except OSError:
        return result
    uid = os.getuid()
    for name in sorted(names):
        segment = _SEGMENT_LOCK.match(name)
        port = _PORT_LOCK.match(name)
        if not (segment or port):
            continue
        lock = Path(directory) / name
        try:
            info = lock.stat()
        except OSError:
            continue
        if info.st_uid != uid or time.time() - info.st_mtime < min_age:
            continue
        if _held_by_a_living_process(lock):
            result.in_use += 1
            continue
        guarded = name[:-3]
        victims = [guarded, name] + ([f"sem.{guarded}_mutex"] if port else [])
        for victim in victims:
            path = Path(directory) / victim
            try:
                size = path.stat().st_size
                path.unlink()
            except OSError:
                continue
            result.removed.append(victim)
            result.removed_bytes += size
    return result
