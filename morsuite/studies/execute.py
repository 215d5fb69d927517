"""Run a dict of Dask tasks on the chosen scheduler, with a progress bar over tasks.

- default: Dask's synchronous scheduler (one task at a time in this process:
  the cleanest timings);
- ``jobs = N > 1``: Dask's local multiprocessing scheduler with N worker processes
  (tasks are plain functions of plain data, so nothing needs a shared interpreter);
- ``scheduler = "tcp://HOST:PORT"`` (or a :class:`distributed.Client`): an existing
  dask.distributed cluster (install the extra ``morsuite[dist]``).

Every task measures its own time; which scheduler ran it goes into the manifest.
"""

from __future__ import annotations

import os
import sys

from ..errors import OptionError

__all__ = ["SchedulerChoice", "choose", "compute", "progress_enabled"]


class SchedulerChoice:
    """Which scheduler runs the graph: ``name`` is synchronous, processes or distributed."""

    def __init__(self, name: str, workers: int = 1, address=None, client=None):
        self.name, self.workers, self.address, self.client = name, workers, address, client

    @property
    def local_files(self) -> bool:
        """True when tasks run on this host and may write the cache themselves."""
        return self.name != "distributed"

    def describe(self) -> dict:
        """The scheduler as plain data for the manifest: name, workers, Dask's version (and the address and distributed's version for a cluster)."""
        import importlib.metadata
        # the version from the metadata: a run that computes nothing does not import dask
        d = {"name": self.name, "workers": self.workers, "dask": importlib.metadata.version("dask")}
        if self.name == "distributed":
            import distributed
            d["address"] = str(self.address)
            d["distributed"] = distributed.__version__
        return d


def choose(jobs=1, scheduler=None) -> SchedulerChoice:
    """Validate ``jobs``/``scheduler`` (before anything is computed)."""
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise OptionError(f"jobs must be a positive integer; got {jobs!r}")
    if scheduler is None:
        return SchedulerChoice("synchronous") if jobs == 1 else SchedulerChoice("processes", jobs)
    if jobs != 1:
        raise OptionError("give either jobs (local processes) or scheduler (a dask.distributed cluster), not both")
    try:
        import distributed
    except ImportError as exc:
        raise OptionError("scheduler needs dask.distributed: pip install 'morsuite[dist]'") from exc
    if isinstance(scheduler, distributed.Client):
        return SchedulerChoice("distributed", len(scheduler.scheduler_info().get("workers", {})),
                               scheduler.scheduler.address, scheduler)
    if not isinstance(scheduler, str) or "://" not in scheduler:
        raise OptionError(f"scheduler must be an address such as tcp://HOST:PORT; got {scheduler!r}")
    return SchedulerChoice("distributed", 0, scheduler)


def progress_enabled(quiet: bool) -> bool:
    """Bars are drawn unless quiet or stderr is not a terminal."""
    return not quiet and sys.stderr.isatty() and os.environ.get("TERM") != "dumb"


def compute(tasks: dict, choice: SchedulerChoice, *, progress: bool = False, desc: str = "tasks",
            file=None) -> dict:
    """Compute the Dask delayed objects ``tasks`` (name -> Delayed); return name -> result.

    ``progress`` draws a tqdm bar over the tasks (to ``file``, default stderr).
    """
    if not tasks:
        return {}
    from tqdm.auto import tqdm

    names = list(tasks)
    with tqdm(total=len(names), desc=desc, unit="task", disable=not progress, leave=False, file=file,
              mininterval=0.2) as bar:
        if choice.name == "distributed":
            values = _distributed(tasks, names, choice, bar)
        else:
            values = _local(tasks, names, choice, bar)
    return dict(zip(names, values))


def _local(tasks, names, choice, bar):
    import dask
    from dask.callbacks import Callback

    wanted = set(names)

    class _Bar(Callback):
        def _posttask(self, key, result, dsk, state, worker_id):
            if key in wanted:
                bar.update(1)

    kw = {"scheduler": "synchronous"} if choice.name == "synchronous" else \
        {"scheduler": "processes", "num_workers": choice.workers}
    with _Bar():
        return dask.compute(*(tasks[n] for n in names), **kw)


def _distributed(tasks, names, choice, bar):
    from distributed import Client, as_completed

    client = choice.client
    own = client is None
    if own:
        client = Client(choice.address, set_as_default=False)
    try:
        choice.workers = len(client.scheduler_info().get("workers", {}))
        futures = client.compute([tasks[n] for n in names])
        for _ in as_completed(futures, loop=client.loop):
            bar.update(1)
        return client.gather(futures)
    finally:
        if own:
            client.close()
