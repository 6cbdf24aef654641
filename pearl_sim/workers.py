"""The studies' worker processes: forked, with the parent's objects left alone in the children.

Every study (`pearl experiment`, the day study, the frame's worlds) runs its episodes in a pool of
forked processes, so the planned controllers are shared copy-on-write instead of pickled. A forked
child inherits the parent's memory, garbage included: the cycles the parent's collector had not
freed yet, among them ROS nodes and contexts of an earlier run in the same process (a test suite,
a notebook). When the child's collector freed those, their finalizers called into a DDS participant
whose threads do not exist in the child, and the child died of a segfault — and a
``multiprocessing`` pool waits for ever for a task whose worker died (seen once in the suite:
``test/test_study.py``'s two-job study after ROS tests in the same worker).

:func:`fork_pool` collects the parent's garbage first (its finalizers run in the parent, where they
work) and freezes what is left (:func:`gc.freeze`: the children's collectors never visit the parent's
objects, which also keeps their pages shared), then forks the pool and unfreezes the parent.
"""
from __future__ import annotations

import contextlib
import gc
import multiprocessing
from typing import Any, Callable, Iterator, Optional, Sequence

__all__ = ["fork_pool"]


@contextlib.contextmanager
def fork_pool(processes: int, initializer: Optional[Callable[..., Any]] = None,
              initargs: Sequence[Any] = ()) -> Iterator[Any]:
    """A ``fork`` pool of ``processes`` workers (``multiprocessing.pool.Pool``), closed on exit; see the
    module doc for what is done to the parent's objects before the workers are forked."""
    gc.collect()
    gc.freeze()
    try:
        pool = multiprocessing.get_context("fork").Pool(int(processes), initializer=initializer,
                                                        initargs=tuple(initargs))
    finally:
        gc.unfreeze()
    with pool:
        yield pool
