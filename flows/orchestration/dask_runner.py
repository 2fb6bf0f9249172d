"""Where a flow's tasks run: threads of this process, or a Dask cluster (``docs/orchestration.md``).

* :func:`task_runner` — Prefect's ``ThreadPoolTaskRunner`` or prefect-dask's ``DaskTaskRunner``
  connected to a running scheduler (``--dask-address tcp://HOST:8786``);
* :func:`local_cluster` — a temporary ``distributed.LocalCluster`` of worker *processes*
  (``--dask-workers N``; the tests and the benchmark use it);
* :func:`shared_api` — the Prefect API the Dask workers report their task runs to. Without
  ``PREFECT_API_URL`` every Prefect process starts its own temporary server, the workers
  included (each would migrate its own SQLite database, ~15 s, and record the runs where
  nobody looks); so when none is configured, one temporary server is started here and its
  address handed to the flow, whose settings travel with every task to the workers. Workers
  on other machines cannot reach it: a real cluster needs a real server
  (``prefect server start --host 0.0.0.0`` and ``PREFECT_API_URL`` for the flow and the workers).
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from typing import Iterator

from flows.common.errors import ValvemonError


def task_runner(concurrency: int, dask_address: str | None = None):
    """The task runner of a flow: threads (at most ``concurrency``) or the Dask scheduler at ``dask_address``."""
    if dask_address:
        from prefect_dask import DaskTaskRunner

        return DaskTaskRunner(address=dask_address)
    from prefect.task_runners import ThreadPoolTaskRunner

    return ThreadPoolTaskRunner(max_workers=max(1, concurrency))


def cluster_threads(dask_address: str, timeout_s: float = 10.0) -> int:
    """Worker threads of the cluster at ``dask_address`` (and a clear error if it is unreachable)."""
    import distributed

    try:
        with distributed.Client(dask_address, timeout=f"{timeout_s}s", set_as_default=False) as client:
            threads = sum(client.nthreads().values())
    except (OSError, TimeoutError, ValueError) as exc:
        raise ValvemonError(f"--dask-address {dask_address}: cannot reach the Dask scheduler ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})") from None
    if threads == 0:
        raise ValvemonError(f"--dask-address {dask_address}: the Dask cluster has no workers")
    return threads


@contextmanager
def local_cluster(n_workers: int, threads_per_worker: int = 1, memory_limit: str | None = "auto") -> Iterator[str]:
    """A temporary local Dask cluster of worker processes; yields the scheduler's address."""
    import distributed

    if n_workers < 1:
        raise ValvemonError("--dask-workers must be at least 1")
    cluster = distributed.LocalCluster(
        n_workers=n_workers,
        threads_per_worker=threads_per_worker,
        processes=True,
        dashboard_address=None,
        memory_limit=memory_limit,
        silence_logs=40,  # logging.ERROR
    )
    try:
        yield cluster.scheduler_address
    finally:
        cluster.close()


@contextmanager
def shared_api() -> Iterator[str | None]:
    """Make sure flow and workers report to one Prefect API (module doc); yields its URL."""
    from prefect.settings import PREFECT_API_URL, PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS, temporary_settings

    url = PREFECT_API_URL.value()
    if url:
        yield url
        return
    from prefect.server.api.server import SubprocessASGIServer

    server = SubprocessASGIServer()  # the process's temporary server, the one a flow would start
    server.start(timeout=PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS.value())
    with temporary_settings(updates={PREFECT_API_URL: server.api_url}):
        os.environ["PREFECT_API_URL"] = server.api_url  # for worker processes started from here
        try:
            yield server.api_url
        finally:
            os.environ.pop("PREFECT_API_URL", None)
