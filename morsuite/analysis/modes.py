r"""Structural validation of reduced models: eigenfrequencies, damping ratios, mode shapes (MAC), structure.

What engineers check before they trust a reduced model (issue 35), as data:

- :func:`model_modes`: the full model's poles in and near a band, with damping ratios and
  right mode shapes (shift-invert Arnoldi on saddle solves,
  :func:`morsuite.linalg.poles.damped_poles`; a few LUs), memoised per model and band.
- :func:`rom_modes`: a reduced model's poles and, where it has a lift ``rom.basis`` (a
  projection-based model, either order), its mode shapes lifted to the full model, :math:`Vq`.
- :func:`match_modes`: the two sets matched by pole distance (optimal assignment), with
  frequency and damping errors and the missing and spurious modes, as a DataFrame.
- :func:`mac`: the modal assurance criterion matrix.
- :func:`structure_checks`: symmetric positive definite :math:`\hat M, \hat K`, semidefinite
  :math:`\hat D`, stability, and (with the full model) the error against the zero model.

Poles are reported one per conjugate pair (:math:`\operatorname{Im}\lambda \ge 0`), natural
frequency :math:`|\lambda|`, damping ratio :math:`-\operatorname{Re}\lambda / |\lambda|`.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import scipy.linalg as sla
from scipy.optimize import linear_sum_assignment

from ..errors import InputError, ShapeError
from ..utils import band_pair
from ..linalg.poles import PolesResult, damped_poles
from ..rom import FirstOrderROM, SecondOrderROM

__all__ = ["model_modes", "rom_modes", "match_modes", "mac", "structure_checks"]


def _band(band, fom=None):
    if band is None:
        if fom is None:
            return None
        band = fom.band
    return band_pair(band, allow_zero=True)


def model_modes(fom, band=None, **options) -> PolesResult:
    r"""The full model's poles, natural frequencies, damping ratios and mode shapes in and near ``band``.

    Parameters
    ----------
    fom : Index3Model
    band : (w1, w2), optional
        rad/s; default ``fom.band``.
    **options
        Passed to :func:`morsuite.linalg.poles.damped_poles` (``k``, ``shifts``, ``n_shifts``,
        ``max_poles``, ``tol``).

    Returns
    -------
    PolesResult
        ``in_band`` flags the poles with :math:`w_1 \le |\lambda| \le w_2`; the others are the
        neighbours the shifts found. Memoised in ``fom.cache`` per band and options: a second
        call costs nothing.

    Cost: one complex sparse LU per shift (one per decade of the band, at most 6) and the
    Arnoldi solves.
    """
    w1, w2 = _band(band, fom)
    key = ("model_modes", w1, w2, tuple(sorted((k, repr(v)) for k, v in options.items())))
    cache = getattr(fom, "cache", None)
    if cache is not None and key in cache:
        return cache[key]
    out = damped_poles(fom, (w1, w2), **options)
    if cache is not None:
        cache[key] = out
    return out


def rom_modes(rom, band=None) -> PolesResult:
    r"""A reduced model's poles, frequencies, damping ratios and lifted mode shapes.

    Second order: the eigenpairs of :math:`(\lambda^2\hat M + \lambda\hat D + \hat K)q = 0`
    (:meth:`SecondOrderROM.eig`), shapes :math:`Vq` (unit 2-norm) where ``rom.basis`` = V is
    known, else None. First order: the eigenpairs of :math:`(A, E)`, shapes :math:`V_1 q` where
    ``rom.basis`` = :math:`V_1` (the position lift of irka-fo and first-order BT) is known.
    Reducers with a lift: modal, krylov, irka, irka-projected, irka-fo, bt and bt-fl (both
    forms); without one: so-h2 (its reduced model is not a projection).

    Parameters
    ----------
    rom : SecondOrderROM or FirstOrderROM
    band : (w1, w2), optional
        Only sets ``in_band`` (all True without a band).

    Returns
    -------
    PolesResult
        One entry per conjugate pair, sorted by frequency; ``shapes`` None without a lift;
        ``residuals``: the reduced eigenproblem's relative residuals.

    Cost: one dense QZ of order 2r (or the first-order state count), plus an n1 x r by r x r
    product for the lift.
    """
    b = _band(band)
    if isinstance(rom, SecondOrderROM):
        lam, Zv = rom.eig(vectors=True)
        Q = Zv[: rom.order]
        up = lam.imag >= 0
        lam, Q = lam[up], Q[:, up]
        Q = Q / np.linalg.norm(Q, axis=0)
        R = rom.K @ Q + (rom.D @ Q) * lam + (rom.M @ Q) * lam ** 2
        scale = (np.abs(lam) ** 2 * np.linalg.norm(rom.M, 1) + np.abs(lam) * np.linalg.norm(rom.D, 1)
                 + np.linalg.norm(rom.K, 1))
        res = np.linalg.norm(R, axis=0) / scale
    elif isinstance(rom, FirstOrderROM):
        lam, Q = sla.eig(rom.A, rom.E, check_finite=False)
        keep = np.isfinite(lam) & (lam.imag >= 0)
        lam, Q = lam[keep], Q[:, keep]
        Q = Q / np.linalg.norm(Q, axis=0)
        R = rom.A @ Q - (rom.E @ Q) * lam
        res = np.linalg.norm(R, axis=0) / (np.abs(lam) * np.linalg.norm(rom.E, 1) + np.linalg.norm(rom.A, 1))
    else:
        raise InputError(f"rom must be a SecondOrderROM or FirstOrderROM; got {type(rom).__name__}")
    basis = getattr(rom, "basis", None)
    shapes = None
    if basis is not None:
        shapes = basis @ Q
        shapes = shapes / np.linalg.norm(shapes, axis=0)
    order = np.argsort(np.abs(lam), kind="stable")
    lam, res = lam[order], res[order]
    if shapes is not None:
        shapes = shapes[:, order]
    freq = np.abs(lam)
    inb = np.ones(lam.size, bool) if b is None else (freq >= b[0]) & (freq <= b[1])
    return PolesResult(poles=lam, shapes=shapes, frequencies=freq,
                       damping=-lam.real / np.where(freq > 0, freq, 1.0), in_band=inb, residuals=res,
                       info={"band": None if b is None else list(b), "lift": shapes is not None})


def match_modes(full: PolesResult, reduced: PolesResult, band=None, *, tol: float = 0.05) -> pd.DataFrame:
    r"""Match the full model's modes in a band with a reduced model's, by pole distance.

    The cost of pairing full pole :math:`\lambda_i` with reduced pole :math:`\hat\lambda_j` is
    :math:`|\lambda_i - \hat\lambda_j| / |\lambda_i|`; an optimal assignment
    (``scipy.optimize.linear_sum_assignment``) over the modes in the band pairs them, and a pair
    counts as matched when its cost is at most ``tol``. Full modes in the band left unmatched
    are *missing*; reduced modes in the band left unmatched are *spurious*.

    Parameters
    ----------
    full, reduced : PolesResult
        From :func:`model_modes` and :func:`rom_modes`.
    band : (w1, w2), optional
        Default: ``full.info["band"]``; modes with natural frequency in it take part.
    tol : float
        Largest relative pole distance of a match (default 0.05).

    Returns
    -------
    pandas.DataFrame
        One row per full mode in the band and per spurious reduced mode, by frequency:
        ``status`` ("matched", "missing", "spurious"), ``full_index``, ``rom_index`` (-1 where
        none), ``freq_full``, ``freq_rom``, ``damping_full``, ``damping_rom``,
        ``rel_freq_error`` :math:`|\hat\omega - \omega| / \omega`, ``damping_error``
        :math:`\hat\zeta - \zeta`, ``pole_distance`` (relative; NaN where unmatched).

    Cost: O(n_full n_rom) plus the assignment.
    """
    b = _band(band if band is not None else full.info.get("band"))
    if b is None:
        raise InputError("band is needed: give band=(w1, w2) (full carries none)")
    if not (isinstance(tol, (int, float)) and tol > 0):
        raise InputError(f"tol must be a positive number; got {tol!r}")
    fi = np.flatnonzero((full.frequencies >= b[0]) & (full.frequencies <= b[1]))
    ri = np.flatnonzero((reduced.frequencies >= b[0]) & (reduced.frequencies <= b[1]))
    pf, pr = full.poles[fi], reduced.poles[ri]
    cost = np.abs(pf[:, None] - pr[None, :]) / np.maximum(np.abs(pf), np.finfo(float).tiny)[:, None]
    rows, cols = linear_sum_assignment(np.where(cost <= tol, cost, 1e6 + cost)) if cost.size else ([], [])
    matched = {int(i): int(j) for i, j in zip(rows, cols) if cost[i, j] <= tol}
    out = []
    nan = float("nan")
    for a, i in enumerate(fi):
        j = matched.get(a)
        rec = {"status": "missing", "full_index": int(i), "rom_index": -1,
               "freq_full": full.frequencies[i], "freq_rom": nan, "damping_full": full.damping[i],
               "damping_rom": nan, "rel_freq_error": nan, "damping_error": nan, "pole_distance": nan}
        if j is not None:
            k = ri[j]
            rec.update(status="matched", rom_index=int(k), freq_rom=reduced.frequencies[k],
                       damping_rom=reduced.damping[k],
                       rel_freq_error=abs(reduced.frequencies[k] - full.frequencies[i]) / full.frequencies[i],
                       damping_error=reduced.damping[k] - full.damping[i], pole_distance=cost[a, j])
        out.append(rec)
    used = set(matched.values())
    for b_, k in enumerate(ri):
        if b_ not in used:
            out.append({"status": "spurious", "full_index": -1, "rom_index": int(k), "freq_full": nan,
                        "freq_rom": reduced.frequencies[k], "damping_full": nan, "damping_rom": reduced.damping[k],
                        "rel_freq_error": nan, "damping_error": nan, "pole_distance": nan})
    df = pd.DataFrame(out, columns=["status", "full_index", "rom_index", "freq_full", "freq_rom", "damping_full",
                                    "damping_rom", "rel_freq_error", "damping_error", "pole_distance"])
    key = df["freq_full"].fillna(df["freq_rom"])
    return df.iloc[np.argsort(key.to_numpy(), kind="stable")].reset_index(drop=True)


def mac(Phi_a, Phi_b, M=None) -> np.ndarray:
    r"""Modal assurance criterion matrix of two sets of mode shapes.

    .. math::

        \mathrm{MAC}_{ij} = \frac{|\varphi_{a,i}^H W \varphi_{b,j}|^2}
                                 {(\varphi_{a,i}^H W \varphi_{a,i})(\varphi_{b,j}^H W \varphi_{b,j})},

    with W = I, or W = M (``M`` given: the mass-weighted MAC). Entries are in [0, 1]; 1 means
    parallel shapes (complex shapes: up to a complex factor). Zero columns give NaN.

    Parameters
    ----------
    Phi_a : array_like (n, ka)
    Phi_b : array_like (n, kb)
    M : sparse or dense (n, n), optional
        Symmetric positive definite weight.

    Returns
    -------
    ndarray (ka, kb)

    Cost: O(n ka kb) (and two products with M).
    """
    A, B = np.asarray(Phi_a), np.asarray(Phi_b)
    if A.ndim == 1:
        A = A[:, None]
    if B.ndim == 1:
        B = B[:, None]
    if A.ndim != 2 or B.ndim != 2 or A.shape[0] != B.shape[0]:
        raise ShapeError(f"Phi_a and Phi_b must be (n, k) arrays with the same n; got {A.shape} and {B.shape}")
    if M is not None and tuple(M.shape) != (A.shape[0], A.shape[0]):
        raise ShapeError(f"M has shape {tuple(M.shape)}; expected {(A.shape[0], A.shape[0])}")
    WB = B if M is None else M @ B
    WA = A if M is None else M @ A
    cross = np.abs(A.conj().T @ WB) ** 2
    na = np.real(np.einsum("ij,ij->j", A.conj(), WA))
    nb = np.real(np.einsum("ij,ij->j", B.conj(), WB))
    with np.errstate(invalid="ignore", divide="ignore"):
        return cross / np.outer(na, nb)


def structure_checks(rom, fom=None, *, rtol: float = 1e-10, omega=None) -> dict:
    r"""Does a reduced model keep the physics? Symmetry, definiteness, stability, and beating zero.

    Second-order models: each of :math:`\hat M, \hat K, \hat D` is symmetric when
    :math:`\|X - X^T\|_1 \le \text{rtol}\,\|X\|_1`; :math:`\hat M` and :math:`\hat K` are
    positive definite when also :math:`\lambda_{\min}(X) > \text{rtol}\,\|X\|_2`, and
    :math:`\hat D` semidefinite when :math:`\lambda_{\min}(\hat D) \ge -\text{rtol}\,\|\hat D\|_2`
    (eigenvalues of the symmetric part, ``eigvalsh``).
    Every model: ``stable`` (``rom.is_stable()``). With ``fom``: ``beats_zero``, the band error
    :math:`\max_\omega\sigma_{\max}(T - \hat T)` below the zero model's
    :math:`\max_\omega\sigma_{\max}(T)` on ``omega`` (:func:`morsuite.utils.worse_than_zero`).

    Parameters
    ----------
    rom : SecondOrderROM or FirstOrderROM
    fom : Index3Model, optional
        The full model, for ``beats_zero`` (costs one sparse LU per frequency of ``omega``).
    rtol : float
        Relative tolerance of the symmetry and definiteness tests (default 1e-10: rounding of
        a projection, not a loss of structure).
    omega : array_like, optional
        Frequencies of the zero-model test; default 40 log-spaced in ``fom.band``.

    Returns
    -------
    dict
        ``second_order``, ``M_spd``, ``K_spd``, ``D_psd``, ``symmetric`` (None for first-order
        models), ``stable``, ``beats_zero`` (None without ``fom``), ``ok`` (every check that
        applies holds), and the measured ``asymmetry``, ``min_eig`` per matrix.

    Cost: dense eigenvalues of r x r matrices and one QZ of order 2r; with ``fom``,
    ``len(omega)`` sparse LUs.
    """
    from ..utils import worse_than_zero
    from .response import errors, freq_grid

    out = {"second_order": isinstance(rom, SecondOrderROM), "M_spd": None, "K_spd": None, "D_psd": None,
           "symmetric": None, "asymmetry": {}, "min_eig": {}}
    if out["second_order"]:
        for name in ("M", "K", "D"):
            X = getattr(rom, name)
            nrm = max(np.linalg.norm(X, 2), np.finfo(float).tiny)
            out["asymmetry"][name] = float(np.linalg.norm(X - X.T, 1) / max(np.linalg.norm(X, 1), np.finfo(float).tiny))
            out["min_eig"][name] = float(sla.eigvalsh(0.5 * (X + X.T))[0]) if X.size else 0.0
            sym = out["asymmetry"][name] <= rtol
            if name == "D":
                out["D_psd"] = bool(sym and out["min_eig"][name] >= -rtol * nrm)
            else:
                out[f"{name}_spd"] = bool(sym and out["min_eig"][name] > rtol * nrm)
        out["symmetric"] = all(v <= rtol for v in out["asymmetry"].values())
    out["stable"] = bool(rom.is_stable())
    out["beats_zero"] = None
    if fom is not None:
        w = freq_grid(fom.band, 40) if omega is None else np.asarray(omega, dtype=float)
        df = errors(fom, rom, w)
        out["band_error"] = float(df["abs_error"].max())
        out["band_norm"] = float(df["sigma_full"].max())
        out["beats_zero"] = not worse_than_zero(band=(out["band_error"], out["band_norm"]))
    checks = [out[k] for k in ("M_spd", "K_spd", "D_psd", "stable", "beats_zero") if out[k] is not None]
    out["ok"] = bool(all(checks))
    return out
