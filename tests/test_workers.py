"""A stopped run stops its workers (morsuite.studies.workers)."""

import multiprocessing
import os
import signal
import subprocess
import sys
import textwrap
import time
from concurrent.futures import ProcessPoolExecutor

import pytest

from morsuite.studies.workers import SIGTERM_STATUS, sigterm_exits, terminate_on_exit

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="process control as on Linux")


def _alive(pid: int) -> bool:
    """The process exists and is not a zombie."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _gone_within(pid: int, seconds: float) -> bool:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if not _alive(pid):
            return True
        time.sleep(0.05)
    return not _alive(pid)


def test_a_failing_block_terminates_running_workers_at_once():
    ctx = multiprocessing.get_context("fork")
    t0 = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        with ProcessPoolExecutor(max_workers=1, mp_context=ctx) as pool, terminate_on_exit(pool):
            pid = pool.submit(os.getpid).result()
            pool.submit(time.sleep, 60)
            time.sleep(0.2)
            raise KeyboardInterrupt
    # without it the pool's shutdown would wait the 60 s of the running task
    assert time.monotonic() - t0 < 20
    assert _gone_within(pid, 5.0)


def test_a_normal_block_leaves_the_pool_alone():
    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("fork")) as pool, \
            terminate_on_exit(pool):
        assert pool.submit(sum, [1, 2, 3]).result() == 6


def test_sigterm_raises_system_exit_inside_the_block_only():
    before = signal.getsignal(signal.SIGTERM)
    with pytest.raises(SystemExit) as info:
        with sigterm_exits():
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(5)  # the handler runs at the next bytecode
    assert info.value.code == SIGTERM_STATUS == 143
    assert signal.getsignal(signal.SIGTERM) is before


def test_a_worker_ends_when_its_parent_is_killed():
    # the parent forks a child that watches it, reports the child's pid once the watch runs, and
    # dies by SIGKILL (no handler, no cleanup): the child must follow within its polling interval
    script = textwrap.dedent("""
        import os, signal, sys, time
        from morsuite.studies.workers import watch_parent
        r, w = os.pipe()
        pid = os.fork()
        if pid == 0:
            watch_parent(interval=0.05)
            os.write(w, b"ready")
            time.sleep(60)
            os._exit(0)
        os.read(r, 5)
        print(pid, flush=True)
        os.kill(os.getpid(), signal.SIGKILL)
    """)
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert out.returncode == -signal.SIGKILL, out.stderr
    child = int(out.stdout.split()[0])
    assert _gone_within(child, 10.0)
