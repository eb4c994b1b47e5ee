"""The batch of batch.py on Dask: one task per log, on local worker processes or on a
dask.distributed cluster.

    rows = run_dask(paths, BatchOptions(), scheduler="local", workers=2, progress=show)
    rows = run_dask(paths, BatchOptions(), scheduler="tcp://head:8786")

Each task is `batch.analyze_one(path, options, identity)`: the worker opens the log
itself (a path travels, never the data), so a remote cluster needs the logs on a file
system its workers share with this host, under the same paths.  A row comes back (a
few hundred bytes), in the order of `paths` whatever order the tasks finish in.

Why processes and one thread each: the work is numpy, scipy and HDF5 decompression,
and HDF5 (h5py) holds a global lock, so threads of one process would mostly wait for
each other.  The local cluster binds to loopback and opens no dashboard unless asked
(`listen`, `dashboard`): nothing is listening beyond this host, and no port can be taken
by another user's dashboard.
"""

from __future__ import annotations

import contextlib
import logging
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
    from dask.distributed import Client, LocalCluster

    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host=host,
                      scheduler_port=port, **http) as cluster, Client(cluster) as client:
        yield client


def _joined(host: str, port: int) -> str:
    """host:port as distributed reads it (an IPv6 host in brackets)."""
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


def run_on(scheduler_client, paths: list[Path], options: BatchOptions = BatchOptions(),
           known: dict[str, dict[str, Any]] | None = None,
           progress: Callable[[int, int], None] | None = None) -> list[dict[str, Any]]:
    """Every log's row, computed by the workers behind `scheduler_client` (a
    dask.distributed.Client), in the order of `paths`;
    `progress(done, total)` after each log."""
    from dask.distributed import as_completed

    known = known or {}
    # keys unique to this call: on a shared cluster another user's batch of the same
    # file names must not be taken for ours
    token = uuid.uuid4().hex[:8]
    # positional iterables are mapped element by element (keywords would be broadcast)
    futures = scheduler_client.map(analyze_one, [str(p) for p in paths], [options] * len(paths),
                         [known.get(str(p)) for p in paths],
                         key=[f"analyze-log-{token}-{i}-{Path(p).name}" for i, p in enumerate(paths)],
                         pure=False)
    index = {f.key: i for i, f in enumerate(futures)}
    rows: list[dict[str, Any] | None] = [None] * len(paths)
    for done, future in enumerate(as_completed(futures), 1):
        i = index[future.key]
        if future.status == "finished":
            rows[i] = future.result()
        else:
            # analyze_one does not raise: this is a worker that died on the log (HDF5
            # crashing the process) or a cluster that went away; the log gets a row
            exc = future.exception()
            rows[i] = error_row(paths[i], f"task failed: {type(exc).__name__}: {exc}")
        future.release()                          # its result is ours now: free the worker
        if progress is not None:
            progress(done, len(paths))
    return rows                                   # type: ignore[return-value]


def run_dask(paths: list[Path], options: BatchOptions = BatchOptions(),
             known: dict[str, dict[str, Any]] | None = None, *, scheduler: str = "local",
             workers: int = 2, listen: Listen | None = None, dashboard: Listen | None = None,
             progress: Callable[[int, int], None] | None = None) -> list[dict[str, Any]]:
    """run_on() with a client made for the call (see dask_client)."""
    with dask_client(scheduler, workers, listen=listen, dashboard=dashboard) as client:
        return run_on(client, paths, options, known, progress)


__all__ = ["dask_client", "run_dask", "run_on"]
