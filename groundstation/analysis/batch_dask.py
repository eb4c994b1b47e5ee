"""The batch of batch.py on Dask: the logs in a few groups of about equal size, one task
per group, on local worker processes or on a dask.distributed cluster.

    rows = run_dask(paths, BatchOptions(), scheduler="local", workers=2, progress=show)
    rows = run_dask(paths, BatchOptions(), scheduler="tcp://head:8786")

A task runs `batch.analyze_one(path, options, identity)` for each log of its group: the
worker opens the log itself (a path travels, never the data), so a remote cluster needs
the logs on a file system its workers share with this host, under the same paths.  Rows
come back (a few hundred bytes each), in the order of `paths` whatever order the tasks
finish in.

Why processes and one thread each: the work is numpy, scipy and HDF5 decompression,
and HDF5 (h5py) holds a global lock, so threads of one process would mostly wait for
each other.  The local cluster binds to loopback and opens no dashboard unless asked
(`listen`, `dashboard`): nothing is listening beyond this host, and no port can be taken
by another user's dashboard.
"""

from __future__ import annotations

import contextlib
import heapq
import logging
import os
import uuid
from pathlib import Path
from typing import Any, Callable, Iterator

from .batch import BatchOptions, analyze_one, error_row

log = logging.getLogger(__name__)


#: a (host, port) to listen on; port 0: the system chooses
Listen = tuple[str, int]


def _port_free(where: Listen, what: str) -> None:
    """Refuse a chosen port that is taken, before any process is started: distributed
    would otherwise warn and move to another port, or fail inside its start-up."""
    from ..link.transports import listening_socket

    if where[1]:
        listening_socket(where[0], where[1], f"choose another port for the {what}, or 0 "
                                             f"for any free one").close()


@contextlib.contextmanager
def dask_client(scheduler: str = "local", workers: int = 2, *, listen: Listen | None = None,
                dashboard: Listen | None = None) -> Iterator[Any]:
    """A dask.distributed Client: on a LocalCluster of `workers` processes (scheduler
    "local"), or connected to the scheduler at `scheduler` (tcp://HOST:8786).  Closed
    (and the local cluster shut down) on leaving.  The local cluster's scheduler listens
    at `listen` (None: 127.0.0.1, a port the system picks), its dashboard at `dashboard`
    (None: no dashboard); a taken port raises PortInUseError."""
    from ..core.errors import GroundStationError

    if scheduler != "local":
        if listen is not None or dashboard is not None:
            raise GroundStationError(
                f"a scheduler or dashboard port is for the local cluster; the cluster at "
                f"{scheduler} has its own (set where its scheduler was started)")
        from dask.distributed import Client

        with Client(scheduler) as client:
            yield client
        return
    host, port = listen or ("127.0.0.1", 0)
    _port_free((host, port), "local Dask scheduler")
    if dashboard is None:
        # without a dashboard the scheduler still serves a few HTTP routes (health,
        # metrics), by default on port 8787: a port any other cluster on this host may
        # hold (then distributed warns and moves).  A free port on the scheduler's
        # host, chosen by the system, never collides.
        http = {"dashboard_address": None,
                "scheduler_kwargs": {"dashboard_address": _joined(host, 0)}}
    else:
        try:
            import bokeh  # noqa: F401
        except ImportError:
            raise GroundStationError("the Dask dashboard needs the bokeh package: "
                                     "pip install 'bokeh>=3.1', or leave the dashboard off") from None
        if dashboard[1] and dashboard[1] == port and dashboard[0] == host:
            raise GroundStationError(f"the Dask scheduler and its dashboard were both given port "
                                     f"{port} on {host}: give them two ports")
        _port_free(dashboard, "Dask dashboard")
        http = {"dashboard_address": _joined(*dashboard)}
    import dask
    from dask.distributed import Client, LocalCluster

    # distributed starts its workers with MALLOC_TRIM_THRESHOLD_=65536, which also fixes
    # glibc's mmap threshold: every large numpy temporary is then mapped and unmapped
    # afresh.  Measured in a worker (24 logs of 60 s): 6,200-6,400 page faults and
    # 115 ms of the task thread's CPU per log, against 1,450-1,850 and 89-92 ms without
    # it or in this process - the third of a log that made Dask lose to the loop.  The
    # workers get the serial loop's thresholds instead (analysis/allocator.py; a value
    # the user exported still wins); one BLAS thread stays.
    from .allocator import WORKER_ENVIRONMENT

    settings = {f"distributed.nanny.pre-spawn-environ.{name}": os.environ.get(name, value)
                for name, value in WORKER_ENVIRONMENT.items()}
    # a worker's profiler samples the task's stack 100 times a second for the
    # dashboard's profile page: 3-4 % of a busy worker's CPU (measured, a 3 s task);
    # off when there is no dashboard to show it
    settings["distributed.worker.profile.enabled"] = dashboard is not None
    if dashboard is None:
        # every process of the cluster wakes its event loop 50 times a second to see
        # whether it was blocked, and samples its CPU and memory twice a second for the
        # dashboard's plots.  In a worker each wake-up takes the interpreter's lock from
        # the task thread; on 2 cores, 8 one-hour logs ran 3-5 % faster with both slowed
        # (docs/scale.md, "Fourth round").  With a dashboard they stay as they were.
        settings["distributed.admin.tick.interval"] = "1s"
        settings["distributed.admin.system-monitor.interval"] = "5s"
    with dask.config.set(settings), \
            LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host=host,
                         scheduler_port=port, **http) as cluster, Client(cluster) as client:
        yield client


def _joined(host: str, port: int) -> str:
    """host:port as distributed reads it (an IPv6 host in brackets)."""
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


#: the cost model behind choosing the serial loop for a small batch (local_cluster_pays),
#: fitted to bench_batch.py on 2 cores (docs/scale.md, "When Dask pays"): the serial
#: loop's seconds per log and per MB of log (60 s logs: 80 ms; 1 h logs: 1.7 s), a local
#: cluster's start, and a worker's time for the same logs over the loop's (scheduling,
#: its event loop, rows sent back)
SERIAL_S_PER_LOG = 0.05
SERIAL_S_PER_MB = 0.0032
CLUSTER_START_S = 2.5
CLUSTER_START_S_PER_WORKER = 0.15
WORKER_SLOWDOWN = 1.35


def local_cluster_pays(sizes: list[int], workers: int) -> tuple[bool, float, float]:
    """(does a local cluster of `workers` finish before the serial loop would, the serial
    loop's estimated seconds, the cluster's estimated seconds including its start) for
    logs of `sizes` bytes.  One worker never pays: it is the serial loop plus a start.
    On the measuring machine the cluster was slower for 100 logs of 60 s and quicker
    for 150; this picks the loop up to about 120."""
    serial = sum(SERIAL_S_PER_LOG + SERIAL_S_PER_MB * b / 1e6 for b in sizes)
    cores = min(workers, os.cpu_count() or 1)
    cluster = (CLUSTER_START_S + CLUSTER_START_S_PER_WORKER * workers
               + serial * WORKER_SLOWDOWN / max(1, cores))
    return workers > 1 and cores > 1 and cluster < serial, serial, cluster


#: tasks per worker: enough that a worker finishing its share early finds another
#: (logs differ in length), few enough that the per-task cost is paid a handful of times
TASKS_PER_WORKER = 4


def log_groups(sizes: list[int], groups: int) -> list[list[int]]:
    """Indices 0..len(sizes)-1 in `groups` groups (fewer if there are fewer logs) of
    about equal total size: the largest log first, each to the lightest group so far
    (longest-processing-time first; the work of a log grows with its bytes).  Each group
    is in index order, the groups in order of their first index."""
    groups = max(1, min(groups, len(sizes)))
    lightest = [(0, g) for g in range(groups)]          # a heap of (load, group)
    members: list[list[int]] = [[] for _ in range(groups)]
    for i in sorted(range(len(sizes)), key=lambda i: (-sizes[i], i)):
        load, g = heapq.heappop(lightest)
        members[g].append(i)
        heapq.heappush(lightest, (load + max(1, sizes[i]), g))
    return sorted((sorted(m) for m in members if m), key=lambda m: m[0])


def analyze_group(paths: list[str], options: BatchOptions,
                  known: list[dict[str, Any] | None]) -> list[dict[str, Any]]:
    """One task: the rows of a group of logs, one after the other in the worker (each by
    analyze_one, which never raises).  Scheduling a task costs the driver about
    11 ms of CPU (docs/scale.md): paid once per group, not per log."""
    return [analyze_one(p, options, k) for p, k in zip(paths, known)]


def _cluster_workers(scheduler_client) -> int:
    try:
        return max(1, len(scheduler_client.scheduler_info().get("workers", {})))
    except Exception:                                  # noqa: BLE001 (an odd scheduler: guess)
        return 1


def run_on(scheduler_client, paths: list[Path], options: BatchOptions = BatchOptions(),
           known: dict[str, dict[str, Any]] | None = None,
           progress: Callable[[int, int], None] | None = None,
           tasks: int | None = None) -> list[dict[str, Any]]:
    """Every log's row, computed by the workers behind `scheduler_client` (a
    dask.distributed.Client), in the order of `paths`; the logs go in `tasks` groups of
    about equal size (None: TASKS_PER_WORKER per worker).  `progress(done, total)` as
    groups finish.  A group whose worker died is run again a log per task, so one log
    that kills its worker costs its own row only."""
    known = known or {}
    sizes = [_size(p) for p in paths]
    groups = log_groups(sizes, tasks or TASKS_PER_WORKER * _cluster_workers(scheduler_client))
    rows: list[dict[str, Any] | None] = [None] * len(paths)
    done = [0]

    def finished(members: list[int], result: list[dict[str, Any]]) -> None:
        for i, row in zip(members, result):
            rows[i] = row
        done[0] += len(members)
        if progress is not None:
            progress(done[0], len(paths))
    failed = _run_groups(scheduler_client, paths, options, known, groups, finished)
    if failed:                  # again, a log a task: find the log that kills a worker
        still = _run_groups(scheduler_client, paths, options, known,
                            [[i] for g in failed for i in g[0]], finished)
        for members, why in still:
            finished(members, [error_row(paths[members[0]], why)])
    return rows                                   # type: ignore[return-value]


def _run_groups(scheduler_client, paths, options, known, groups: list[list[int]],
                finished) -> list[tuple[list[int], str]]:
    """Submit one task per group; hand each finished group's rows to `finished`; return
    the groups whose task failed, with why."""
    from dask.distributed import as_completed

    # keys unique to this call: on a shared cluster another user's batch of the same
    # file names must not be taken for ours
    token = uuid.uuid4().hex[:8]
    futures = {}
    for members in groups:
        first = Path(paths[members[0]]).name
        future = scheduler_client.submit(
            analyze_group, [str(paths[i]) for i in members], options,
            [known.get(str(paths[i])) for i in members],
            key=f"analyze-logs-{token}-{members[0]}-{len(members)}-{first}", pure=False)
        futures[future.key] = (future, members)
    failed = []
    for future in as_completed([f for f, _ in futures.values()]):
        members = futures[future.key][1]
        if future.status == "finished":
            finished(members, future.result())
        else:
            # analyze_one does not raise: this is a worker that died on a log (HDF5
            # crashing the process) or a cluster that went away
            exc = future.exception()
            failed.append((members, f"task failed: {type(exc).__name__}: {exc}"))
        future.release()                          # its result is ours now: free the worker
    return failed


def _size(path: Path) -> int:
    try:
        return Path(path).stat().st_size
    except OSError:
        return 0


def run_dask(paths: list[Path], options: BatchOptions = BatchOptions(),
             known: dict[str, dict[str, Any]] | None = None, *, scheduler: str = "local",
             workers: int = 2, listen: Listen | None = None, dashboard: Listen | None = None,
             progress: Callable[[int, int], None] | None = None) -> list[dict[str, Any]]:
    """run_on() with a client made for the call (see dask_client)."""
    with dask_client(scheduler, workers, listen=listen, dashboard=dashboard) as client:
        return run_on(client, paths, options, known, progress)


__all__ = ["analyze_group", "dask_client", "local_cluster_pays", "log_groups", "run_dask", "run_on"]
