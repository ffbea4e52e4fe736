"""The ``dask`` executor: fanned-out items on a Dask distributed cluster.

- ``address`` empty/null: a ``LocalCluster`` is started on 127.0.0.1 (loopback only) with
  ``n_workers`` worker processes of ``threads_per_worker`` threads each, used for one fanned-out
  step and closed afterwards.
- ``address: tcp://host:8786``: an existing scheduler (``dask scheduler`` + ``dask worker`` on your
  machines, or a cluster started by dask-jobqueue / dask-kubernetes). Its workers must import the
  same twinkit and plugins, and see the site's ``outputs/<site>/.cache`` at the same path (shared
  file system): each item writes its result into that store itself, under its file lock.
- ``cluster: slurm``: a ``dask_jobqueue.SLURMCluster`` is started with the ``slurm_*`` settings
  and scaled to ``n_workers`` jobs (needs ``pip install 'twinkit-tiles[jobqueue]'``).

``map(fn, items)`` submits every item (``client.map``, ``pure=False``) and yields the results in
the items' order; the cluster it started is closed even when the run stops early.
"""
from __future__ import annotations

from typing import Any, Callable, Iterator


class DaskExecutor:
    def __init__(self, address: str | None = None, n_workers: int = 2, threads_per_worker: int = 1,
                 memory_limit: str = "auto", cluster: str = "local", slurm: dict | None = None):
        self.address = address or None
        self.n_workers = max(1, int(n_workers))
        self.threads_per_worker = max(1, int(threads_per_worker))
        self.memory_limit = memory_limit
        self.cluster_kind = cluster
        self.slurm = dict(slurm or {})
        self.last_workers: list[str] = []

    def _start(self):
        from distributed import Client, LocalCluster

        if self.address:
            return Client(self.address, timeout="30s"), None
        if self.cluster_kind == "slurm":
            cluster = slurm_cluster(n_jobs=self.n_workers, **self.slurm)
            return Client(cluster), cluster
        if self.cluster_kind != "local":
            from twinkit.errors import ConfigError

            raise ConfigError(f"executor=dask: unknown cluster '{self.cluster_kind}' (local or slurm)")
        cluster = LocalCluster(n_workers=self.n_workers, threads_per_worker=self.threads_per_worker,
                               processes=True, host="127.0.0.1", dashboard_address=None,
                               memory_limit=self.memory_limit, silence_logs=40)
        return Client(cluster), cluster

    def map(self, fn: Callable[[Any], Any], items: list[Any]) -> Iterator[Any]:
        if not items:
            return
        client, cluster = self._start()
        try:
            self.last_workers = sorted(client.scheduler_info().get("workers", {}))
            futures = client.map(fn, items, pure=False)
            for fut in futures:
                yield fut.result()
        finally:
            client.close()
            if cluster is not None:
                cluster.close()


def slurm_cluster(n_jobs: int = 2, queue: str = "", cores: int = 4, memory: str = "16GB",
                  walltime: str = "02:00:00", account: str = "", python: str = "", **extra):
    """A dask-jobqueue SLURMCluster with one worker process per job, scaled to ``n_jobs`` jobs.
    Example (not run here; there is no SLURM on this machine)::

        twinkit recipe=tiled_site site=big executor=dask executor.cluster=slurm executor.n_workers=8 \\
            executor.slurm.queue=cpu executor.slurm.cores=8 executor.slurm.memory=32GB
    """
    try:
        from dask_jobqueue import SLURMCluster
    except ImportError:
        from twinkit.errors import ConfigError

        raise ConfigError("executor.cluster=slurm needs dask-jobqueue: .venv/bin/pip install 'twinkit-tiles[jobqueue]'") from None
    kw = dict(cores=int(cores), processes=1, memory=memory, walltime=walltime, **extra)
    if queue:
        kw["queue"] = queue
    if account:
        kw["account"] = account
    if python:
        kw["python"] = python
    cluster = SLURMCluster(**kw)
    cluster.scale(jobs=int(n_jobs))
    return cluster
