"""The studies' worker processes: forked, with the parent's objects left alone in the children, and a
worker that dies reported instead of waited for.

Every study (`pearl experiment`, the day study, the frame's worlds) runs its episodes in a pool of
forked processes, so the planned controllers are shared copy-on-write instead of pickled. A forked
child inherits the parent's memory, garbage included: the cycles the parent's collector had not
freed yet, among them ROS nodes and contexts of an earlier run in the same process (a test suite,
a notebook). When the child's collector freed those, their finalizers called into a DDS participant
whose threads do not exist in the child, and the child died of a segfault; the
``multiprocessing.Pool`` the studies used then waited for ever for the dead worker's task (seen once in
the suite: ``test/test_study.py``'s two-job study after ROS tests in the same worker process).

:func:`fork_pool` collects the parent's garbage first (its finalizers run in the parent, where they
work) and freezes what is left while the workers are forked (:func:`gc.freeze`: the children's
collectors never visit the parent's objects, which also keeps their pages shared), then unfreezes
the parent. Its pool is a :class:`concurrent.futures.ProcessPoolExecutor`, which notices a worker
that died: the study stops with :class:`~pearl_pomdp.errors.PearlError` naming the exit instead of
hanging.
"""
from __future__ import annotations

import concurrent.futures
import contextlib
import gc
import multiprocessing
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Callable, Iterator, Optional, Sequence

from pearl_pomdp.errors import PearlError

__all__ = ["fork_pool"]


@contextlib.contextmanager
def fork_pool(processes: int, initializer: Optional[Callable[..., Any]] = None,
              initargs: Sequence[Any] = ()) -> Iterator[concurrent.futures.ProcessPoolExecutor]:
    """``processes`` forked workers as a ``ProcessPoolExecutor`` (``pool.map(fn, items, chunksize=k)``:
    the results in order), shut down on exit; see the module doc for what is done to the parent's
    objects before the workers are forked.

    Raises:
        PearlError: a worker process died (a signal, the out-of-memory killer) before its tasks were done.
    """
    pool = concurrent.futures.ProcessPoolExecutor(int(processes), mp_context=multiprocessing.get_context("fork"),
                                                  initializer=initializer, initargs=tuple(initargs))
    try:
        gc.collect()
        gc.freeze()
        try:
            # With fork the executor starts every worker at its first task: start them now, frozen.
            pool.submit(int).result()
        finally:
            gc.unfreeze()
        yield pool
    except BrokenProcessPool as err:
        raise PearlError(f"a study worker process died before its tasks were done ({err}); "
                         "nothing of the study was lost in this process, but it cannot go on") from None
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
