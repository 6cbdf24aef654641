"""The study's episodes on a Dask cluster: ``pearl experiment --cluster ADDRESS``.

A study that outgrows one machine runs its cells on the workers of a running Dask
``distributed`` scheduler (``dask scheduler`` on one machine, ``dask worker ADDRESS
--nthreads 1`` on each of the others, every one with this package installed). The planned
policies, the domain, the residents' cases and the speech channels are sent to every worker
once (``scatter(broadcast=True)``); the episodes go out in batches and come back in cell
order, and every episode is seeded by its cell alone — so the result is the one
``--jobs N`` gives, bit for bit (``test/test_cluster.py`` checks it on a local cluster).

One episode runs at a time per worker process (a lock): the planned policies are shared
by the worker's threads and are not written for concurrent use, so extra threads wait
instead of risking a different result; start workers with ``--nthreads 1`` and as many
processes as cores (``--nworkers``).

Nothing here is needed without ``--cluster``: ``distributed`` is imported only then.
"""
from __future__ import annotations

import threading
from typing import Any, List, Optional, Sequence

from pearl_pomdp.errors import PearlError

__all__ = ["ClusterError", "connect", "run_on_cluster", "DEFAULT_TIMEOUT"]

#: Seconds to wait for the scheduler to answer before giving up (``--cluster-timeout``).
DEFAULT_TIMEOUT = 10.0
#: Episodes per task sent to a worker: large enough that scheduling costs little against
#: the episodes (~0.1-0.3 s each), small enough to spread a small grid over the workers.
BATCH = 16

_EPISODE_LOCK = threading.Lock()


class ClusterError(PearlError):
    """The cluster cannot be reached or used (the message names the address)."""


def connect(address: str, timeout: float = DEFAULT_TIMEOUT):
    """A ``distributed.Client`` on the scheduler at ``address``.

    Raises:
        ClusterError: ``distributed`` is not installed, or no scheduler answered at
            ``address`` within ``timeout`` seconds.
    """
    try:
        from distributed import Client
    except ImportError:
        raise ClusterError("--cluster needs Dask's `distributed` package: pip install -e '.[cluster]'") from None
    try:
        return Client(address, timeout=timeout, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as err:
        raise ClusterError(f"--cluster {address}: no Dask scheduler answered within {timeout:g} s "
                           f"({type(err).__name__}: {str(err).splitlines()[0] if str(err) else 'no reply'})") from None


def _run_batch(payload: dict, batch: Sequence[Any]) -> list:
    """On a worker: the episodes of ``batch`` in order (one at a time per process)."""
    import logging

    from pearl_sim.nursing_home.study import run_job

    # As in the parent: the tracker's per-step recovery messages would flood the worker's log.
    logging.getLogger("pearl_pomdp").setLevel(logging.ERROR)
    with _EPISODE_LOCK:
        return [run_job(payload, job) for job in batch]


def run_on_cluster(address: str, payload: dict, work: Sequence[Any], progress: bool = False,
                   timeout: Optional[float] = None, batch: int = BATCH) -> List[Any]:
    """Run every ``(policy, cell)`` of ``work`` on the cluster; the episodes in ``work``'s order.

    Args:
        address: the scheduler, e.g. ``tcp://10.0.0.5:8786``.
        payload: what every episode needs (:func:`pearl_sim.nursing_home.study.run_job`'s ``work``).
        work: the jobs.
        progress: a bar on stderr as batches finish.
        timeout: seconds to wait for the scheduler (default :data:`DEFAULT_TIMEOUT`).
        batch: jobs per task.

    Raises:
        ClusterError: the scheduler does not answer, or it has no worker.
    """
    from tqdm import tqdm

    client = connect(address, DEFAULT_TIMEOUT if timeout is None else timeout)
    try:
        if not client.scheduler_info().get("workers"):
            client.wait_for_workers(1, timeout=DEFAULT_TIMEOUT if timeout is None else timeout)
        [shared] = client.scatter([payload], broadcast=True, hash=False)
        batches = [list(work[i:i + batch]) for i in range(0, len(work), batch)]
        futures = [client.submit(_run_batch, shared, b, pure=False) for b in batches]
        results: List[list] = []
        bar = tqdm(total=len(work), desc="study (cluster)", disable=not progress, leave=False)
        for future, jobs in zip(futures, batches):   # in cell order; the workers run ahead
            results.append(future.result())
            bar.update(len(jobs))
        bar.close()
        return [episode for chunk in results for episode in chunk]
    except TimeoutError:
        raise ClusterError(f"--cluster {address}: the scheduler has no worker "
                           f"(start `dask worker {address}`)") from None
    finally:
        client.close()
