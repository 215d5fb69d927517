"""Worker processes that end with the run that started them.

``morsuite run`` computes on a pool of worker processes (:mod:`morsuite.studies.batch`) and draws
figures on forked ones (:mod:`morsuite.studies.outputs`). Stopped from outside, the run must not
leave them computing: a pool's ``with`` block waits for its running tasks, which may take an hour
on a finite-element model, and a parent killed outright leaves its children behind (seen
2026-11-28: the two workers of an FE study whose run was stopped by SIGTERM computed on).
Three pieces, each cheap:

- :func:`terminate_on_exit`: around a pool's use, any exception (``KeyboardInterrupt``, the
  ``SystemExit`` of :func:`sigterm_exits`, a failed unit) cancels the queued tasks and terminates
  the workers before the pool's own shutdown waits for them;
- :func:`sigterm_exits`: the command's SIGTERM raises ``SystemExit(143)`` in the main thread, so
  the above runs (the default action ends the process without cleanup);
- :func:`watch_parent`: a worker's initializer starts a daemon thread that ends the worker when
  its parent is gone (a SIGKILL of the run): polled every ``interval`` seconds.

How many workers ``morsuite run`` starts by default (:func:`default_jobs`): one per usable core,
bounded by memory: the available memory (``MemAvailable`` of ``/proc/meminfo``) divided by a
worker's estimate, :data:`WORKER_BASE_MIB` plus :data:`WORKER_KIB_PER_POSITION` per position of
the largest model of the run's studies, and at least one. The estimate is the most a worker was
measured to hold (``docs/design/reports.md``): 234 MiB for the interpreter with the reducers
imported and the kernels loaded (2026-12-02), and 56 KiB per position for BT's LR-ADI factors
and kept LUs on the TCOM at n1 = 1e5 (5.6 GB of RSS, ``results/bench/scaling.csv``; IRKA about
3 KiB, the DSMS's BT 6 KiB), so that workers of a study at n1 = 2e4 take 1.5 GiB each.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time

__all__ = ["terminate_on_exit", "sigterm_exits", "watch_parent", "usable_cores", "available_memory", "default_jobs",
           "cpu_seconds", "WORKER_BASE_MIB", "WORKER_KIB_PER_POSITION"]

#: exit status of a command stopped by SIGTERM (128 + 15, as a shell reports it)
SIGTERM_STATUS = 128 + signal.SIGTERM

#: a worker's memory before its first unit (interpreter, numpy, scipy, pandas, the reducers, the kernels): MiB
WORKER_BASE_MIB = 256.0
#: a worker's memory per position (n1) of the largest model it may meet: KiB (the most measured: BT on the TCOM)
WORKER_KIB_PER_POSITION = 64.0


@contextlib.contextmanager
def terminate_on_exit(pool):
    """Terminate ``pool``'s worker processes when the block raises; re-raise.

    ``pool``: a :class:`concurrent.futures.ProcessPoolExecutor`. Queued tasks are cancelled and
    each live worker gets SIGTERM (its result is lost: the block failed anyway). Use inside the
    pool's ``with`` so that its shutdown then finds no running task. Cost: nothing when the
    block returns normally.
    """
    try:
        yield pool
    except BaseException:
        procs = list((getattr(pool, "_processes", None) or {}).values())  # shutdown forgets them
        pool.shutdown(wait=False, cancel_futures=True)
        for proc in procs:
            if proc.is_alive():
                proc.terminate()
        raise


@contextlib.contextmanager
def sigterm_exits():
    """Within the block, SIGTERM raises ``SystemExit(143)`` in the main thread (restored after).

    Outside the main thread (where Python cannot install handlers) the block runs unchanged.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def _exit(signum, frame):
        raise SystemExit(SIGTERM_STATUS)

    old = signal.signal(signal.SIGTERM, _exit)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


def watch_parent(interval: float = 1.0) -> threading.Thread:
    """Start a daemon thread that ends this process (``os._exit(1)``) once its parent is gone.

    For a pool worker's initializer: a worker whose run was killed outright (SIGKILL, no handler)
    is re-parented, which the thread sees within ``interval`` seconds (default 1). Returns the
    thread. Cost: one ``getppid`` per interval.
    """
    parent = os.getppid()

    def _watch():
        while os.getppid() == parent:
            time.sleep(interval)
        os._exit(1)

    thread = threading.Thread(target=_watch, name="morsuite-watch-parent", daemon=True)
    thread.start()
    return thread


def usable_cores() -> list:
    """The cores this process may run on (``os.sched_getaffinity``), sorted."""
    try:
        return sorted(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return list(range(os.cpu_count() or 1))


def available_memory():
    """Bytes of memory available to new processes (``MemAvailable`` of ``/proc/meminfo``; else the free
    physical pages), or None where neither can be read."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, OSError, ValueError):
        return None


def default_jobs(n1_max: int, cores=None, available=None) -> dict:
    r"""The default number of worker processes of ``morsuite run``: the usable cores, bounded by memory.

    .. math::

        \text{jobs} = \max\Bigl(1, \min\Bigl(\text{cores},
        \Bigl\lfloor \frac{\text{available}}{B + c\,n_{1,\max}} \Bigr\rfloor\Bigr)\Bigr),

    B = :data:`WORKER_BASE_MIB`, c = :data:`WORKER_KIB_PER_POSITION` (module docstring).

    Parameters
    ----------
    n1_max : int
        Positions of the largest model the workers may build.
    cores : list, optional
        The usable cores (default :func:`usable_cores`).
    available : int or None, optional
        Bytes of available memory (default :func:`available_memory`; None there: no memory bound).

    Returns
    -------
    dict
        ``jobs``, ``cores`` (their count), ``available_mib``, ``worker_mib`` (the estimate),
        ``by_memory`` (workers that fit, None without a memory figure) and ``rule`` (one line).
    """
    n_cores = len(usable_cores() if cores is None else cores)
    available = available_memory() if available is None else available
    worker = WORKER_BASE_MIB + WORKER_KIB_PER_POSITION * max(int(n1_max), 0) / 1024.0
    by_memory = None if available is None else int(available / 2 ** 20 // worker)
    jobs = max(1, n_cores if by_memory is None else min(n_cores, by_memory))
    return {"jobs": jobs, "cores": n_cores, "available_mib": None if available is None else available / 2 ** 20,
            "worker_mib": worker, "by_memory": by_memory,
            "rule": f"min(usable cores, available memory / ({WORKER_BASE_MIB:g} MiB + {WORKER_KIB_PER_POSITION:g} KiB "
                    f"x n1 of the largest model)), at least 1"}


def cpu_seconds(who: str = "both") -> float:
    """User + system CPU seconds, all threads, from ``getrusage``.

    ``who``: ``"self"`` (this process), ``"children"`` (its children that have ended and were waited
    for: a study's figure processes, a run's workers once the pool is shut down) or ``"both"``
    (default). What ``morsuite run`` records per unit and per run (``run.json``): on a machine shared
    with other jobs it grows with their load far less than wall time (the main job's units: 296 s of
    CPU at load 3, 376 s at load 7 to 10, against 235 and 1092 s of wall time;
    ``docs/design/reports.md``). Cost: two system calls.
    """
    import resource

    out = 0.0
    for name, kind in (("self", resource.RUSAGE_SELF), ("children", resource.RUSAGE_CHILDREN)):
        if who in (name, "both"):
            use = resource.getrusage(kind)
            out += use.ru_utime + use.ru_stime
    return out
