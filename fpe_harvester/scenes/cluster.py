"""Scene points on a Dask cluster (optional extra: ``pip install "fpe-harvester[dask]"``).

Each point that needs a pointwise solver (Fokker--Planck, Monte Carlo) becomes one task;
the client (the process that runs the scene) receives the results as they finish and
appends each to the scene's cache at once, so the cache stays the single record of what is
done and workers never write to it. Points carry their seed and Monte Carlo replica batch
(:meth:`.run._Runner.method_of`), so a point gives the same numbers on any worker, in any
order, as in one process. Each task takes one worker thread: Monte Carlo runs
single-threaded there unless the scene sets ``threads``.

A worker lost mid-run costs only the points it was computing: the scheduler hands them to
another worker. A point that takes down ``distributed.scheduler.allowed-failures`` + 1
workers in a row (default 3 + 1, e.g. out of memory) is reported as failed on its row and
tried again on the next run, like any failed point.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from typing import Any, Self

from ..errors import ParameterError

__all__ = ["LOCAL", "Connection", "run_tasks"]

#: ``scheduler`` value that starts a LocalCluster on this machine.
LOCAL = "local"


def _distributed(scheduler: object) -> Any:
    try:
        import distributed
    except ImportError as exc:
        raise ParameterError(
            f"scheduler {scheduler!r} needs Dask, which is not installed: "
            f'pip install "fpe-harvester[dask]" (it failed with: {exc})') from exc
    return distributed


class Connection:
    """The Dask client of one scene run: checked at once, connected when first needed.

    A scene whose points are all harmonic (or cached) never starts a cluster or contacts the
    scheduler. Use as a context manager; :meth:`close` closes what was opened here.

    Parameters
    ----------
    scheduler : str or distributed.Client
        ``"local"``: a LocalCluster on this machine with ``workers`` single-threaded worker
        processes (default: one per usable CPU); an address such as
        ``"tcp://10.0.0.5:8786"``: that running scheduler; a Client: used as is (not closed).
    workers : int or None
        Worker processes of the LocalCluster, >= 1; must be ``None`` otherwise (a running
        cluster has its own workers).

    Raises
    ------
    ParameterError
        Dask is not installed, ``scheduler`` is of the wrong type, or ``workers`` is given
        for a running cluster; on first use (:meth:`client`), the scheduler cannot be reached.
    """

    def __init__(self, scheduler: Any, workers: int | None = None) -> None:
        self._dd = _distributed(scheduler)
        given = isinstance(scheduler, self._dd.Client)
        if not given and (not isinstance(scheduler, str) or not scheduler):
            raise ParameterError(f"scheduler must be 'local', a scheduler address or a distributed.Client, "
                                 f"got {scheduler!r} (type {type(scheduler).__name__})")
        if workers is not None and scheduler != LOCAL:
            where = "the given client" if given else f"the cluster at {scheduler!r}"
            raise ParameterError(f"workers={workers!r} only applies to local processes or "
                                 f"scheduler='local': {where} has its own workers")
        self.scheduler, self.workers = scheduler, workers
        self._client: Any = scheduler if given else None
        self._opened: list[Any] = []

    def client(self) -> Any:
        """The connected ``distributed.Client`` (started or connected on the first call)."""
        if self._client is not None:
            return self._client
        dd = self._dd
        if self.scheduler == LOCAL:
            from fpe_harvester.parallel import default_threads

            cluster = dd.LocalCluster(n_workers=self.workers or default_threads(), threads_per_worker=1,
                                      processes=True)
            self._opened.append(cluster)
            self._client = dd.Client(cluster)
        else:
            try:
                self._client = dd.Client(self.scheduler)
            except (OSError, TimeoutError, ValueError) as exc:
                raise ParameterError(f"cannot reach the Dask scheduler at {self.scheduler!r}: {exc}") from exc
        self._opened.insert(0, self._client)
        return self._client

    def close(self) -> None:
        """Close the client and cluster opened here (a given client stays open)."""
        while self._opened:
            self._opened.pop(0).close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def run_tasks(client: Any, fn: Callable[..., Any], args: Sequence[tuple[Any, ...]],
              failed: Callable[[int, str], Any]) -> Iterator[tuple[int, Any]]:
    """Submit ``fn(*a)`` for each ``a`` in ``args``; yield ``(index, result)`` as tasks finish.

    A task that the cluster could not run (its workers kept dying, or it did not unpickle)
    yields ``failed(index, reason)`` instead. Tasks still pending when the caller stops
    (interrupt, error) are cancelled.
    """
    distributed = _distributed(client)
    # pure=False: every point is its own task, even two that look alike
    futures = client.map(fn, *zip(*args), pure=False)
    index = {fut.key: i for i, fut in enumerate(futures)}
    try:
        for fut in distributed.as_completed(futures):
            i = index[fut.key]
            try:
                yield i, fut.result()
            except distributed.KilledWorker as exc:
                yield i, failed(i, f"the Dask workers running this point kept dying ({exc}); "
                                   "check their memory and logs")
            except Exception as exc:  # noqa: BLE001 - one point's trouble must not sink the sweep
                yield i, failed(i, f"the Dask task failed: {type(exc).__name__}: {exc}")
    finally:
        client.cancel([f for f in futures if not f.done()])
