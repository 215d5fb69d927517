"""Small shared helpers: atomic file writes, plain data, BLAS threads, and the
worse-than-the-zero-model flag of reported errors (:func:`worse_than_zero`)."""

from __future__ import annotations

import contextlib
import contextvars
from concurrent.futures import ThreadPoolExecutor
import math
import os
import tempfile
from numbers import Real
from pathlib import Path

import numpy as np

__all__ = ["atomic_path", "atomic_write_text", "to_plain", "strict_json", "band_pair", "worse_than_zero",
           "default_threads", "map_threads", "load_average"]


@contextlib.contextmanager
def atomic_path(path, suffix=None):
    """Yield a temporary path next to ``path``; rename it onto ``path`` on success.

    An interrupted write leaves either the old file or the new one, never a
    truncated mix.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix or path.suffix, dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        # mkstemp creates 0600 files; give the result the usual umask permissions
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def atomic_write_text(path, text: str):
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        Path(tmp).write_text(text)


def to_plain(x):
    """Numpy scalars/arrays, tuples, complex numbers and Paths -> JSON-friendly data.

    Complex numbers become ``{"re": ..., "im": ...}``
    (:func:`morsuite.reducers.base.as_complex` reverses that).
    """
    if isinstance(x, dict):
        return {str(k): to_plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [to_plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return to_plain(x.tolist())
    if isinstance(x, np.bool_):
        return bool(x)
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.floating):
        return float(x)
    if isinstance(x, (complex, np.complexfloating)):
        return {"re": float(x.real), "im": float(x.imag)}
    if isinstance(x, Path):
        return str(x)
    return x


def strict_json(x):
    """Non-finite floats as strings ("inf", "nan"), so that ``json.dumps(..., allow_nan=False)`` holds."""
    if isinstance(x, dict):
        return {k: strict_json(v) for k, v in x.items()}
    if isinstance(x, list):
        return [strict_json(v) for v in x]
    if isinstance(x, float) and not np.isfinite(x):
        return str(x)
    return x


def band_pair(band, *, name: str = "band", allow_zero: bool = False) -> tuple[float, float]:
    """``(lo, hi)`` of a frequency band, checked, else an InputError naming ``name``.

    ``0 < lo < hi < inf``; with ``allow_zero`` (a band from zero: modes, band Gramians)
    ``0 <= lo < hi < inf``, each failure said apart (not a pair, not finite, negative, empty).
    Cost O(1).
    """
    from .errors import InputError

    try:
        lo, hi = (float(b) for b in band)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be a pair (lo, hi) of numbers in rad/s; got {band!r}") from exc
    if not allow_zero:
        if not (0 < lo < hi < np.inf):
            raise InputError(f"{name} must satisfy 0 < lo < hi < inf; got {band}")
        return lo, hi
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise InputError(f"{name} must be finite; got {band!r}")
    if lo < 0:
        raise InputError(f"{name} must lie in [0, inf) (negative frequencies are included by symmetry); "
                         f"got w1 = {lo:g}")
    if not lo < hi:
        raise InputError(f"{name} must satisfy 0 <= w1 < w2 (finite, rad/s): the band is empty; got {band!r}")
    return lo, hi


_CONTROLLER = None


def blas_threads(limit: int = 1):
    """Context limiting BLAS to ``limit`` threads (threadpoolctl).

    One ThreadpoolController per process: building one scans the loaded
    libraries (3.4 ms, more than a cached BT reduction costs). The dense work
    of morsuite is on n1 x k blocks and small matrices, where BLAS threads only
    add synchronisation; on this 2-core machine idle OpenBLAS threads spinning
    next to SuperLU slowed a frequency response by 15% (measured).
    """
    global _CONTROLLER
    if _CONTROLLER is None:
        from threadpoolctl import ThreadpoolController
        _CONTROLLER = ThreadpoolController()
    return _CONTROLLER.limit(limits=limit, user_api="blas")


def default_threads(backend: str) -> int:
    """The automatic ``solver_threads``: 2 on two or more cores, else 1; always 1 for ``"klu"``.

    IRKA's shift solves, frequency-limited BT's nodes and the full model's samples of a band
    response (:func:`morsuite.analysis.band_response`) use it. Measured on a quiet moment of
    this 2-core machine (docs/design/backends.md): six LUs of
    dsms(2e5) or tcom(2e5) on 2 threads took 0.46-0.55 of the serial time with SuperLU and
    0.48-0.64 with the banded LU (0.70-0.79 with their solves). BLAS runs single-threaded
    inside a reduction (``reducers.base.BLAS_THREADS``), so the threads do not compete
    with BLAS threads. More than 2 was not measured. KLU through nbklu holds the GIL for
    its numeric factorization (measured 2026-11-27: a Python loop in another thread ran about 1/70
    of its iterations during the call; kvxopt, the former KLU, held it too), so threads cannot
    overlap its LUs. rslab's factorizations and PARDISO's calls (ctypes) release the GIL.
    """
    if backend == "klu":
        return 1
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    return 2 if cores >= 2 else 1


def map_threads(fn, jobs, threads: int) -> list:
    """``[fn(j) for j in jobs]`` on a pool of ``threads`` threads (serial for one thread or one job).

    Each job runs in a copy of the caller's context (:mod:`contextvars`), so that what the caller
    has opened there (the solve-accuracy record of :func:`morsuite.linalg.accuracy.recording`)
    sees the job's work too."""
    if threads <= 1 or len(jobs) <= 1:
        return [fn(j) for j in jobs]
    contexts = [contextvars.copy_context() for _ in jobs]  # a context is entered by one thread at a time
    with ThreadPoolExecutor(max_workers=min(threads, len(jobs))) as pool:
        return list(pool.map(lambda pair: pair[0].run(fn, pair[1]), zip(contexts, jobs)))


def _judged(pair):
    """(error, reference) as floats, or None when the pair cannot be judged."""
    if pair is None:
        return None
    err, ref = pair
    if not all(isinstance(x, Real) and not isinstance(x, bool) for x in (err, ref)):
        return None
    err, ref = float(err), float(ref)
    if math.isnan(err) or math.isnan(ref) or math.isinf(ref):
        return None
    return err, ref


def worse_than_zero(**pairs) -> list[str]:
    r"""The norms in which a reduced model's error is at or above the zero model's.

    The zero model :math:`T_r = 0` has error :math:`\|T - 0\| = \|T\|` in every norm, at no
    cost. A reduced model with :math:`\|T - T_r\| \ge \|T\|` is no approximation in that
    norm, whatever its other merits (e.g. the paper's IRKA at r = 2 on a 3x3 MIMO chain in
    the band norm): the study tables, ``morsuite reduce/simulate --json`` and the verdict
    texts say so through this function (also exported as
    :func:`morsuite.analysis.worse_than_zero`; a leaf, so that a cached study imports no
    numerics). The values compared are the ones reported (the H-infinity values are the
    largest peaks found, lower bounds).

    Parameters
    ----------
    **pairs : (float, float) or None
        ``name=(error, reference)`` per norm: :math:`\|T - T_r\|` and :math:`\|T\|` in that
        norm. The names morsuite uses: ``band`` (:math:`\max_\omega \sigma_{\max}(T - T_r)`
        and :math:`\max_\omega \sigma_{\max}(T)` on one grid), ``h2``, ``hinf``, and for a
        simulation ``max_output`` (:math:`\max_t \|y - y_r\|_2` against
        :math:`\max_t \|y\|_2`) and ``l2_output`` (the same in :math:`L_2` over the horizon).
        A relative error may be passed as ``(rel, 1.0)``. A norm given as None, or with a
        None or NaN value or an infinite reference, is not judged.

    Returns
    -------
    list of str
        The names with ``error >= reference`` (an infinite error, of an unstable reduced
        model, counts), in the order given; empty when the reduced model beats the zero
        model in every norm judged. Cost: none.
    """
    out = []
    for name, pair in pairs.items():
        p = _judged(pair)
        if p is not None and p[0] >= p[1]:
            out.append(name)
    return out


def load_average():
    """The machine's 1, 5 and 15 minute load averages (``os.getloadavg``), rounded to 0.01, or None
    where the platform has none: what a timing taken on a shared machine records beside it. Cost: one
    system call."""
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except (AttributeError, OSError):  # pragma: no cover - not on this platform
        return None
