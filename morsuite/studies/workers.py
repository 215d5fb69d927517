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
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time

__all__ = ["terminate_on_exit", "sigterm_exits", "watch_parent", "usable_cores"]

#: exit status of a command stopped by SIGTERM (128 + 15, as a shell reports it)
SIGTERM_STATUS = 128 + signal.SIGTERM


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
