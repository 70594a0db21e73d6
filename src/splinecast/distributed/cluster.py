"""A local Dask cluster for rendering: single-threaded worker processes with a quiet background.

A Dask ``LocalCluster`` with its default settings keeps every process busy even when no task runs:
each worker samples its own stack every 10 ms for the dashboard's profile page, every event loop
checks that it is not blocked every 20 ms, each nanny measures its worker's memory every 100 ms,
and every process polls its CPU, memory, network and disk counters twice a second. On this
project's 2-core test machine that came to about 0.15 of a core for an idle 2-worker cluster
(client and scheduler 55 ms/s, each worker 45 ms/s), and more while tasks run (the profiler then
walks the rendering thread's stack). With one worker there is a spare core to absorb it; with as
many workers as cores it comes straight out of the renders, and it was most of what kept a
movie on 2 workers from being twice as fast as on one.

:func:`local_cluster` starts the cluster with :data:`QUIET_CONFIG` instead, which brings the idle
cost to about 0.02 of a core. What it gives up: the dashboard's profile page stays empty, a blocked
event loop is noticed after 0.5 s instead of 20 ms, and a worker's memory limit is enforced within
0.5 s instead of 0.1 s. Clusters a user starts are left as they are (their workers read their own
Dask configuration); set the same keys there for the same effect.
"""

from __future__ import annotations

from typing import Any

__all__ = ["QUIET_CONFIG", "local_cluster"]

#: Dask settings of :func:`local_cluster` (see the module docstring for what each costs).
QUIET_CONFIG: dict[str, Any] = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "500ms",
    "distributed.worker.memory.monitor-interval": "500ms",
    "distributed.admin.system-monitor.interval": "2s",
    "distributed.admin.system-monitor.disk": False,
}


def local_cluster(workers: int, threads_per_worker: int = 1,
                  config: dict[str, Any] | None = None, **kwargs: Any) -> Any:
    """A ``distributed.LocalCluster`` of ``workers`` processes with a quiet background.

    Parameters
    ----------
    workers : int
        Worker processes.
    threads_per_worker : int
        Threads of each worker (1: one single-threaded render per process, the layout the
        movie and tile batches are measured with).
    config : dict, optional
        Dask settings applied on top of :data:`QUIET_CONFIG` (e.g.
        ``{"distributed.worker.profile.enabled": True}`` to get the profile page back).
    **kwargs
        Other ``LocalCluster`` arguments; by default the dashboard takes any free port and the
        worker logs stay quiet below errors (a user mistake is reported once, by the client).

    Returns
    -------
    distributed.LocalCluster
        Close it (or use it as a context manager) when done.
    """
    import dask
    from distributed import LocalCluster

    options = {"processes": True, "dashboard_address": ":0", "silence_logs": 40, **kwargs}
    # The scheduler and the nannies read these when they are created, and each nanny hands its
    # copy of the configuration to the worker process it starts: setting them for the duration
    # of the start-up is enough and leaves this process's configuration as it was.
    with dask.config.set({**QUIET_CONFIG, **(config or {})}):
        return LocalCluster(n_workers=workers, threads_per_worker=threads_per_worker,
                            **options)
