"""Frequency-response analysis: sigma_max, error tables, grids."""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..linalg.dense import sigma_max  # public here too (ms.analysis.sigma_max); reducers take it from linalg

__all__ = ["sigma_max", "errors", "freq_grid", "band_response"]


def freq_grid(band, n: int = 200) -> np.ndarray:
    """``n`` log-spaced frequencies (rad/s) over ``band = (lo, hi)``."""
    try:
        lo, hi = (float(b) for b in band)
    except (TypeError, ValueError) as exc:
        raise InputError(f"band must be a pair (lo, hi) of numbers; got {band!r}") from exc
    if not (0 < lo < hi) or int(n) < 1:
        raise InputError(f"band must satisfy 0 < lo < hi and n >= 1; got band={band}, n={n}")
    return np.logspace(np.log10(lo), np.log10(hi), int(n))


def errors(fom, rom, omega, *, H_full=None):
    """Error table of a reduced model on a frequency grid.

    Parameters
    ----------
    fom : Index3Model (or anything with ``freqresp``)
    rom : reduced model with ``freqresp``
    omega : array_like, rad/s
    H_full : ndarray, optional
        Precomputed ``fom.freqresp(omega)``: pass it when comparing several
        reduced models on one grid so that the full model is solved once.

    Returns
    -------
    pandas.DataFrame
        Columns omega, sigma_full, sigma_rom, abs_error
        (:math:`\\sigma_{max}(T - T_r)`), rel_error (abs_error / sigma_full; inf where
        only the full response vanishes, 0 where both do).
    """
    import pandas as pd

    omega = np.asarray(omega, dtype=float)
    Hf = fom.freqresp(omega) if H_full is None else np.asarray(H_full)
    if Hf.shape[0] != omega.size:
        raise InputError(f"H_full has {Hf.shape[0]} frequencies; omega has {omega.size}")
    Hr = rom.freqresp(omega)
    if Hr.shape != Hf.shape:
        raise InputError(f"reduced response has shape {Hr.shape}; full has {Hf.shape}")
    sf = sigma_max(Hf)
    ea = sigma_max(Hf - Hr)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(sf > 0, ea / sf, np.where(ea > 0, np.inf, 0.0))  # 0/0: both responses vanish
    return pd.DataFrame({"omega": omega, "sigma_full": sf, "sigma_rom": sigma_max(Hr),
                         "abs_error": ea, "rel_error": rel})


def band_response(fom, omega, *, progress: bool = False, threads: int = 0):
    r"""The full model's response on a grid, drawn from and kept in the model's memo of :math:`T(j\omega)`.

    The values of :meth:`Index3Model.freqresp <morsuite.models.Index3Model.freqresp>` (one LU per
    frequency, its solves at the backward-error target of :mod:`morsuite.linalg.accuracy`, refined
    against the exact :math:`S(j\omega)` in extended precision until the estimated error is below
    double's rounding; the LU's own values until 2026-12-02), computed through
    :meth:`FomResponse.sample <morsuite.norms._fom.FomResponse.sample>`: each sample is also
    given its derivative :math:`T'(j\omega)` (one transposed solve), and kept with the LU's value
    in ``fom.cache``, so that the H-infinity searches of the model and of its
    reduced models (:func:`~morsuite.analysis.hinf_norm` and :func:`~morsuite.analysis.hinf_error`
    with ``band_grid``) pay no LU at these frequencies; a frequency already kept costs none here.

    Parameters
    ----------
    fom : Index3Model
    omega : array_like
        Frequencies (rad/s), real, finite, non-negative.
    progress : bool
        Draw a progress bar.
    threads : int
        Threads that factor and solve the frequencies concurrently, each with its own solver
        (0, default: :func:`morsuite.utils.default_threads` of the model's backend, as IRKA's
        shift solves: 2 on two or more cores, 1 for KLU, which holds the GIL). Each sample depends
        on its frequency only: the values are the same, to the bit, for every thread count.

    Returns
    -------
    H : ndarray, complex (len(omega), p, m)
    lu_count : int
        LUs made by this call (at most ``len(omega)``).
    """
    from ..utils import blas_threads, default_threads, map_threads
    from ..norms._fom import FomResponse

    w = np.atleast_1d(np.asarray(omega, dtype=float))
    if w.ndim != 1 or w.size == 0 or not np.all(np.isfinite(w)) or np.any(w < 0):
        raise InputError(f"omega must be a non-empty 1-D array of finite frequencies >= 0; got shape {w.shape}")
    if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or threads < 0:
        raise InputError(f"threads must be a non-negative integer; got {threads!r}")
    ev = FomResponse(fom, refine=1, memo=True)
    threads = min(int(threads) or default_threads(ev.solver.backend), w.size)
    out = np.empty((w.size, fom.p, fom.m), dtype=complex)
    bar = None
    if progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=w.size, desc=f"freqresp {fom.name}", unit="freq", leave=False)
    # one response (own solver and LU cache) per thread, the frequencies dealt out in turn
    evs = [ev] + [FomResponse(fom, refine=1, memo=True) for _ in range(threads - 1)]

    def run(k):
        for i in range(k, w.size, threads):
            out[i] = evs[k].sample(1j * w[i])[1]  # the refined value (the LU's, [0], stays in the memo)
            if bar is not None:
                bar.update(1)
    with blas_threads(1):
        map_threads(run, list(range(threads)), threads)
    if bar is not None:
        bar.close()
    return out, sum(e.lu_count for e in evs)
