"""Where sweep points run: a Dask `distributed` client on an embedded local cluster (no set-up) or on an existing
cluster (`--scheduler tcp://HOST:PORT`; its workers need only the installed package)."""
from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator

import dask
from distributed import Client, LocalCluster

from sea_hil.errors import ConfigError

# no dashboard, and the scheduler's remaining HTTP server (health, metrics) on an ephemeral port: with
# `dashboard_address=None` alone it still tries the fixed 8787 first (distributed 2026.8), so two sweeps at once warn
NO_DASHBOARD = {"dashboard": False, "dashboard_address": "127.0.0.1:0"}
# the embedded cluster's own bookkeeping, slowed down: by default the scheduler, each nanny and each worker sample
# CPU, memory and disk I/O with psutil every 0.5 s and each nanny its worker's memory every 0.1 s, in the client
# process and the workers, which share the machine's cores with the points (a dashboard would show these samples;
# the embedded cluster has none). The memory limit still holds, checked every second.
QUIET_MONITORS = {"distributed.admin.system-monitor.interval": "5s", "distributed.admin.system-monitor.disk": False,
                  "distributed.worker.memory.monitor-interval": "1s"}


@contextlib.contextmanager
def open_client(scheduler: str | None, jobs: int, engine: str = "offline") -> Iterator[Client]:
    """A `distributed.Client`. Without `scheduler`, a local cluster (no dashboard, closed on exit): engine `offline`
    computes in the worker (CPU and GIL bound), so `jobs` worker processes of one thread; engine `lockstep` points
    are child processes a thread waits on, so one in-process worker with `jobs` threads (no GIL cost)."""
    if scheduler is None:
        with dask.config.set(QUIET_MONITORS):
            if engine == "offline":
                cluster = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True, dashboard_address=None,
                                       scheduler_kwargs=NO_DASHBOARD, silence_logs=logging.WARNING)
            else:
                cluster = LocalCluster(n_workers=1, threads_per_worker=jobs, processes=False, dashboard_address=None,
                                       scheduler_kwargs=NO_DASHBOARD, silence_logs=logging.WARNING)
            try:
                with Client(cluster) as client:
                    yield client
            finally:
                cluster.close()
        return
    try:
        client = Client(scheduler, timeout="10s")
    except (OSError, TimeoutError) as err:
        raise ConfigError(f"--scheduler {scheduler}: cannot reach the Dask scheduler ({err})") from err
    try:
        yield client
    finally:
        client.close()
