"""What every benchmark records and writes: machine, code state, JSON, tables, figures.

- :func:`machine_info`: CPUs, platform, versions, BLAS, thread variables, load
  (the ``machine`` entry of ``manifest.json``).
- :func:`code_state`: git HEAD, uncommitted files and SHA-256 digests of the modules
  that decide the timings, so that a result says which code it measured.
- :func:`write_json`: plain-data JSON (NumPy scalars and arrays, paths), atomically;
  :func:`rewrite_derived`: recompute what a saved result derives from its measurements.
- :func:`resolve_out_dir`: where a benchmark writes its CSV, Markdown and PNG files.
- :func:`write_table` (``stem``.csv and ``stem``.md), :func:`new_figure`,
  :func:`save_png`: atomic files, no pyplot state.
"""

from __future__ import annotations

import contextvars
import json
import os
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np

from ..utils import atomic_path

__all__ = ["machine_info", "code_state", "write_json", "json_default", "rewrite_derived", "resolve_out_dir",
           "write_table", "new_figure", "save_png", "THREAD_ENV_VARS"]

THREAD_ENV_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                   "BLIS_NUM_THREADS", "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")

#: the ``out_dir`` of the :func:`morsuite.bench.run` call in progress (benchmark functions
#: take only ``quick``: this is how they learn where their extra files go)
CURRENT_OUT_DIR: contextvars.ContextVar = contextvars.ContextVar("morsuite_bench_out_dir", default=None)


# ---------------------------------------------------------------------------
# machine and code
# ---------------------------------------------------------------------------

def _blas_info() -> dict:
    try:
        cfg = np.show_config(mode="dicts")
    except TypeError:  # numpy < 1.25: no mode argument
        return {"available": False}
    deps = (cfg or {}).get("Build Dependencies", {})
    return {k: deps[k] for k in ("blas", "lapack") if k in deps}


def machine_info() -> dict:
    """Plain data about the machine and the software that produced a timing."""
    import scipy

    from .. import __version__

    info = {
        "cpu_count": os.cpu_count(),
        "platform": platform.platform(),
        "machine": platform.machine(),
        "processor": platform.processor(),
        "python": sys.version.split()[0],
        "versions": {"morsuite": __version__, "numpy": np.__version__, "scipy": scipy.__version__},
        "threads_env": {k: os.environ.get(k) for k in THREAD_ENV_VARS},
        "blas": _blas_info(),
    }
    if hasattr(os, "sched_getaffinity"):
        info["cpus_usable"] = len(os.sched_getaffinity(0))
    try:
        info["load_average"] = list(os.getloadavg())
    except (AttributeError, OSError):
        pass
    return info


#: modules whose content decides the timings; hashed into every result (the tree may be
#: edited while a long benchmark runs)
_KEY_MODULES = ("linalg/saddle.py", "linalg/saddle_lu.py", "linalg/lradi.py", "linalg/adi_iteration.py",
                "linalg/adi_shifts.py", "linalg/manifold.py", "linalg/system.py", "linalg/dense.py",
                "linalg/orthonormal.py", "linalg/refine.py", "linalg/backends.py", "linalg/backends_ext.py",
                "linalg/backends_rslab.py",
                "reducers/irka/second_order.py", "reducers/irka/engine.py", "reducers/irka/shift_update.py",
                "reducers/irka/safeguards.py", "reducers/bt/balanced.py", "reducers/irka/projected.py",
                "reducers/base.py", "models/index3.py", "rom.py")


def code_state(git: bool = True) -> dict:
    """The code a measurement ran: git HEAD and dirty files (read-only git), and short SHA-256
    hashes of the modules that decide the timings (``digest`` combines them)."""
    import hashlib

    pkg = Path(__file__).resolve().parent.parent
    hashes = {}
    for rel in _KEY_MODULES:
        try:
            hashes[rel] = hashlib.sha256((pkg / rel).read_bytes()).hexdigest()[:12]
        except OSError:
            hashes[rel] = None
    state = {"modules": hashes,
             "digest": hashlib.sha256(json.dumps(hashes, sort_keys=True).encode()).hexdigest()[:12]}
    if git:
        def _git(*args):
            try:
                out = subprocess.run(["git", *args], cwd=pkg.parent, capture_output=True, text=True, timeout=20)
                return out.stdout.strip() if out.returncode == 0 else None
            except (OSError, subprocess.SubprocessError):
                return None
        state["git_head"] = _git("rev-parse", "HEAD")
        dirty = _git("status", "--porcelain", "--", "morsuite")
        state["git_dirty"] = dirty.splitlines() if dirty else []
    return state


# ---------------------------------------------------------------------------
# files
# ---------------------------------------------------------------------------

def json_default(x):
    """``json.dumps`` fallback: NumPy scalars and arrays as Python data, anything else as ``str``."""
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    return str(x)


def write_json(path, data):
    """``data`` as indented JSON at ``path``, atomically."""
    text = json.dumps(data, indent=2, default=json_default)
    with atomic_path(Path(path)) as tmp:
        Path(tmp).write_text(text + "\n")


def rewrite_derived(out_dir, name: str, derive, write_outputs) -> list[Path]:
    """Recompute the derived part of ``out_dir``/``name``.json without measuring again.

    ``derive(result)`` updates the loaded result in place (tables, verdicts,
    ratios from the stored rows); ``write_outputs(result, out_dir)`` writes its
    files again; the JSON is rewritten with the new ``files`` list. Returns the files.
    """
    out = Path(out_dir)
    res = json.loads((out / f"{name}.json").read_text())
    derive(res)
    files = write_outputs(res, out)
    res["files"] = [str(p) for p in files]
    write_json(out / f"{name}.json", res)
    return files


def resolve_out_dir(out_dir=None) -> Path:
    """Where a benchmark writes its CSV, Markdown and PNG files.

    ``out_dir`` if given; else the ``out_dir`` of the :func:`morsuite.bench.run`
    call in progress; else ``$MORSUITE_BENCH_OUT``; else ``results/bench``.
    """
    if out_dir is not None:
        return Path(out_dir)
    current = CURRENT_OUT_DIR.get()
    if current is not None:
        return Path(current)
    return Path(os.environ.get("MORSUITE_BENCH_OUT") or "results/bench")


def write_table(df, stem, *, title: str = "", note: str = "", md_columns=None) -> list[Path]:
    """``stem``.csv (every column, full precision) and ``stem``.md (``md_columns``, 6 digits), atomically."""
    from ..report.tables import write_table as _write_table

    return _write_table(df, stem, title=title, note=note, md_columns=md_columns)


def new_figure(ncols: int = 1, width: float = 6.0, height: float = 4.2):
    """A matplotlib Figure on the Agg canvas (no pyplot state) and its axes."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width * ncols, height), layout="constrained")
    axes = fig.subplots(1, ncols, squeeze=False)[0]
    return fig, list(axes)


def save_png(fig, path) -> Path:
    """Write ``fig`` to ``path`` (PNG, 130 dpi) atomically."""
    from ..report.figures import save

    path = Path(path)
    return save(fig, path.with_suffix(""), formats=("png",), dpi=130)[0]
