"""What the manifest records about the machine: versions, BLAS, host, threads."""

from __future__ import annotations

import importlib.metadata
import os
import platform
import sys

__all__ = ["environment"]

_PACKAGES = ("numpy", "scipy", "control", "slycot", "pandas", "matplotlib", "dask", "distributed", "tqdm")
_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
                "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")


def _version(pkg):
    try:
        return importlib.metadata.version(pkg)
    except importlib.metadata.PackageNotFoundError:
        return None


def _blas() -> dict:
    import numpy as np
    try:
        cfg = np.show_config(mode="dicts")
        deps = cfg.get("Build Dependencies", {})
        return {k: {kk: deps[k].get(kk) for kk in ("name", "version", "openblas configuration")
                    if deps[k].get(kk) is not None} for k in ("blas", "lapack") if k in deps}
    except Exception:  # older numpy: no dict mode; the version list still says enough
        return {}


def _plain_info(value):
    """A threadpool_info value as JSON data: scipy's Matrix Market reader (loaded by
    models.load_mtx) registers a pool whose ``version`` is a function, not a string."""
    if callable(value):
        try:
            value = value()
        except Exception:  # noqa: BLE001 - a version we cannot read is recorded as unknown
            return None
    return value if value is None or isinstance(value, (str, int, float, bool)) else str(value)


def _threads() -> dict:
    out = {"cpu_count": os.cpu_count(), "env": {v: os.environ.get(v) for v in _THREAD_VARS if v in os.environ}}
    try:
        out["affinity"] = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        pass
    try:
        from threadpoolctl import threadpool_info
        out["threadpools"] = [{k: _plain_info(d.get(k)) for k in ("internal_api", "num_threads", "version")}
                              for d in threadpool_info()]
    except ImportError:
        pass
    return out


def environment() -> dict:
    """The machine and software a run used, for ``manifest.json``.

    Returns
    -------
    dict
        ``versions`` (morsuite, Python and the numerical packages), ``blas`` (the
        BLAS/LAPACK NumPy is linked to), ``host`` (name, platform, machine,
        processor) and ``threads`` (CPU count, affinity, the thread environment
        variables set, threadpoolctl's pools when it is installed).
    """
    from .. import __version__
    return {
        "versions": {"morsuite": __version__, "python": sys.version.split()[0],
                     **{p: _version(p) for p in _PACKAGES}},
        "blas": _blas(),
        "host": {"name": platform.node(), "platform": platform.platform(), "machine": platform.machine(),
                 "processor": platform.processor() or None},
        "threads": _threads(),
    }
