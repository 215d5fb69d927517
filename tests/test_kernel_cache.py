"""The compiled kernels load from numba's on-disk cache: a fresh process compiles nothing again, and its
first reduction costs little more than a warm one (issue 47, item 6).

A subprocess populates the cache (the warm-up compiles whatever is missing), a second fresh one reduces
dsms(1000) with IRKA at r = 4 twice. Its reference is itself: the second, warm reduction, and numba's
own start-up (``import numba`` and a trivial cached function: numba's type registries; about 0.33 s
on the 2-core machine of 2026-12-02), paid before the first timer, so that the bound is on what
morsuite adds (the kernels' loads and the warm-up's own work: about 0.09 s there, quiet).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from morsuite.linalg import kernels

pytestmark = pytest.mark.skipif(not kernels.use_kernels(), reason="the compiled kernels are off")

ROOT = Path(__file__).resolve().parents[1]

_SCRIPT = textwrap.dedent("""
    import json, sys, time
    import numpy as np
    import morsuite as ms
    import morsuite.reducers  # importing the package is not the reduction
    fom = ms.models.dsms(g=1000)
    omega = 1j * np.logspace(-2, 0, 5)
    sys.path.insert(0, sys.argv[1])
    t0 = time.perf_counter()
    import numba, _trivial  # numba's own start: its import and its first cached function
    _trivial.f(1.0)
    floor = time.perf_counter() - t0
    times, responses = [], []
    for _ in range(2):
        t0 = time.perf_counter()
        res = ms.reducers.make("irka", fom).reduce(4)
        times.append(time.perf_counter() - t0)
        responses.append([res.rom.transfer(s).ravel().tolist() for s in omega])
    from morsuite.linalg import _dd_jit, kernels
    dispatchers = list(kernels._JIT.values()) + [_dd_jit.entries, _dd_jit.product]
    print(json.dumps({"floor": floor, "times": times,
                      "re": [np.real(responses).tolist(), np.imag(responses).tolist()],
                      "compiled": {d.py_func.__qualname__: len(d.signatures) for d in dispatchers},
                      "misses": {d.py_func.__qualname__: sum(d.stats.cache_misses.values()) for d in dispatchers}}))
""")


_POPULATE = textwrap.dedent("""
    import sys
    sys.path.insert(0, sys.argv[1])
    import _trivial
    from morsuite.linalg.warmup import warm_kernels
    _trivial.f(1.0)
    warm_kernels()
    print("{}")
""")


def _run(tmp_path, script=_SCRIPT):
    env = {k: v for k, v in os.environ.items() if k != "MORSUITE_BAND_KERNEL"}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    out = subprocess.run([sys.executable, "-c", script, str(tmp_path)], capture_output=True, text=True,
                         timeout=600, cwd=ROOT, env=env)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_fresh_process_loads_kernels_from_cache(tmp_path):
    """After one process has run the warm-up, a fresh one compiles no kernel (every overload a reduction uses
    is a cache hit: the warm-up covers them all) and its first and second reductions give the same reduced
    model (to rounding). The time is not asserted (a timed assertion fails on a loaded machine): the first
    reduction against the warm one is printed by this test's JSON and measured in docs/design/backends.md (the kernels' cache)."""
    (tmp_path / "_trivial.py").write_text("from numba import njit\n\n\n@njit(cache=True)\n"
                                          "def f(x):\n    return x + 1.0\n")
    _run(tmp_path, _POPULATE)  # the warm-up alone populates numba's cache with all a reduction needs
    run = _run(tmp_path)
    assert sum(run["compiled"].values()) >= 10, run["compiled"]  # the kernels ran (both dtypes, dd residual)
    assert not any(run["misses"].values()), f"kernels compiled again in a fresh process: {run['misses']}"
    re, im = (np.asarray(x) for x in run["re"])
    h1, h2 = re[0] + 1j * im[0], re[1] + 1j * im[1]
    assert np.max(np.abs(h1 - h2)) <= 1e-10 * np.max(np.abs(h2)), "the first and the warm reduction differ"
