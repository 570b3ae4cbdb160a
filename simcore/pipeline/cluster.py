"""Tasks on Dask that never wait for ever: a cluster without workers, an unreachable scheduler or a worker that
keeps dying ends in one line (:class:`~simcore.errors.ClusterError`) instead of a hang or a traceback.

Dask retries a task whose worker died (``distributed.scheduler.allowed-failures`` times, 3 by default) and then
raises ``KilledWorker``; a cluster that has no worker left (or never had one) would keep the tasks queued for
ever, so :func:`run_tasks` polls the number of workers while it waits and gives up after ``NO_WORKER_WAIT_S``
without any. What finished before is kept by the callers (run files, evaluation files): a rerun resumes.
"""
import time

from simcore.errors import ClusterError

# seconds a run waits for its first (or next) worker before giving up: a cluster's workers connect within seconds
# of being started; a minute without any means none is coming
NO_WORKER_WAIT_S = 60.0
# seconds between looks at the cluster while no task finishes
POLL_S = 2.0


def _client(scheduler, workers):
    from dask.distributed import Client, LocalCluster
    if scheduler:
        try:
            return Client(scheduler, timeout=f"{NO_WORKER_WAIT_S}s"), None
        except (OSError, TimeoutError) as exc:
            raise ClusterError(f"cannot reach the Dask scheduler at {scheduler} ({type(exc).__name__}: {exc}); "
                               "check --scheduler, or leave it out for a local cluster") from None
    # ':0': the scheduler's HTTP server on a free port, so two studies (or a sweep) can run at once
    cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True, dashboard_address=":0")
    return Client(cluster), cluster


def run_tasks(fn, items, *, scheduler=None, workers=2, on_done=None, what="task"):
    """Run ``fn(*item)`` for each of ``items`` on Dask (a running ``scheduler``'s address, else a local cluster of
    ``workers`` processes); call ``on_done(item, result)`` as each finishes. Raise ClusterError when no worker is
    there for NO_WORKER_WAIT_S, or when a worker died running an item more often than Dask retries it."""
    from distributed import KilledWorker, wait
    client, cluster = _client(scheduler, workers)
    try:
        futures = {client.submit(fn, *item, pure=False): item for item in items}
        pending, idle_since = set(futures), None
        while pending:
            try:
                done, pending = wait(pending, timeout=POLL_S, return_when="FIRST_COMPLETED")
            except TimeoutError:
                done = set()
            for fut in done:
                try:
                    result = fut.result()
                except KilledWorker:
                    raise ClusterError(f"a Dask worker died each time it ran the {what} {futures[fut]} (killed: out "
                                       "of memory?); what finished is kept: free memory or use fewer --workers, and "
                                       "run the same command again to resume") from None
                if on_done is not None:
                    on_done(futures[fut], result)
            if done:
                idle_since = None
                continue
            if client.scheduler_info().get("workers"):
                idle_since = None
            elif idle_since is None:
                idle_since = time.monotonic()
            elif time.monotonic() - idle_since > NO_WORKER_WAIT_S:
                where = f"the Dask scheduler at {scheduler}" if scheduler else "the local Dask cluster"
                raise ClusterError(f"{where} has had no worker for {NO_WORKER_WAIT_S:g} s, so {len(pending)} "
                                   f"{what}(s) cannot run; what finished is kept: start workers (dask worker "
                                   f"{scheduler or 'ADDRESS'}) and run the same command again to resume")
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
