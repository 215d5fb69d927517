r"""A saved reduced model checked against its model: the recorded errors computed again (``morsuite verify``).

:func:`verify_rom` takes a model and a reduced model read by :func:`morsuite.load_rom` with its
sidecar (:mod:`morsuite.romfiles`), and compares every error the sidecar recorded with the same
quantity computed again, within the accuracy each one states:

model hash
    :func:`morsuite.romfiles.model_hash` of the model given must equal the recorded one;
    otherwise the model is another one: a warning, and the check fails (the errors are still
    computed where the sizes allow, to show how far they are).
band errors
    On the recorded grid (:func:`morsuite.romfiles.grid_omega`), with
    :func:`morsuite.analysis.errors`: the largest :math:`\sigma_{\max}(T - T_r)` (``band max
    error``), the largest :math:`\sigma_{\max}(T)` (``band peak``) and the largest pointwise
    relative error. The full model's response is sampled by
    :func:`~morsuite.analysis.band_response` (one LU per frequency; the LU's value, as the
    recorded one was until 2026-12-02, kept in the model's memo) and refined in extended precision (:class:`~morsuite.norms._fom.FomResponse`):
    the refined :math:`T` is the reference, and :math:`\delta(\omega) = \sigma_{\max}(T_0 - T)`,
    the LU value's measured error, gives its level :math:`\rho = \max_\omega \delta(\omega) /
    \sigma_{\max}(T(j\omega))`. The recorded value came from an LU of another run (another
    backend, ordering or machine): frequency by frequency its error differs from this one's by
    orders of magnitude (where one is small by chance), its level by a small factor (measured,
    ``docs/design/romfiles.md``). The allowance at :math:`\omega` is
    :math:`(c\rho + 16\varepsilon)\,\sigma_{\max}(T(j\omega))` (:math:`c` = :data:`LU_FACTOR`,
    16 = :data:`ROUNDING`), plus the same for the reduced model's dense solves (against their
    extended-precision refinement) with :math:`\sigma_{\max}(T_r(j\omega))`; the
    :math:`16\varepsilon` covers rounding the values to double and their singular values. A
    maximum over the grid moves by at most the largest allowance; a pointwise relative error
    by the allowance over :math:`\sigma_{\max}(T)` (less the allowance) times :math:`1 +` itself.
H2 error and norm
    Computed again by :func:`~morsuite.analysis.error_norms` with the recorded options. Each
    value is within its floor of the exact one, so two values agree when they differ by at
    most the sum of their floors, plus :data:`ROUNDING` :math:`\varepsilon` times their sum
    (the final rounding, which no floor counts). A value without a finite floor is not judged.
H-infinity error and norm
    Enclosures: a certified value is the interval [lower bound, upper bound], an uncertified
    one a lower bound only. Two certified enclosures must overlap; a lower bound must not
    exceed a certified upper bound; two lower bounds without a certificate are the same peak
    found twice and must agree to the peak search's ``rtol`` (relative). Slack:
    :data:`ROUNDING` :math:`\varepsilon` times the sum of the values.

A quantity the sidecar does not hold (``--no-norms`` at saving, a failed norm) is shown as
not recorded and not judged.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from ..errors import AccuracyWarning, InputError
from ..norms._fom import FomResponse
from ..norms._rom import RomResponse, first_order_arrays
from ..romfiles import grid_omega, model_hash
from .compare import error_norms
from .response import band_response, errors, sigma_max

__all__ = ["LU_FACTOR", "ROUNDING", "verify_rom", "table_lines"]

EPS = float(np.finfo(float).eps)
#: allowance for another run's LU error, in units of the error measured here (docs/design/romfiles.md)
LU_FACTOR = 10.0
#: rounding slack, in units of the double precision unit times the values compared
ROUNDING = 16.0


def _num(x):
    """A recorded number (the sidecar writes non-finite ones as strings), or None."""
    if x is None or isinstance(x, bool):
        return None
    try:
        return float(x)
    except (TypeError, ValueError):
        return None


def _row(quantity, recorded, recomputed, accuracy, rule, agrees, **extra):
    return {"quantity": quantity, "recorded": recorded, "recomputed": recomputed, "accuracy": accuracy,
            "rule": rule, "agrees": agrees, **extra}


def _within(quantity, rec, new, accuracy, rule):
    """A row judged by ``|rec - new| <= accuracy`` (not judged when a value or the accuracy is missing)."""
    if rec is None:
        return _row(quantity, None, new, accuracy, "not recorded", None)
    if new is None or accuracy is None or not np.isfinite(accuracy):
        return _row(quantity, rec, new, accuracy, rule + "; not judged (no finite accuracy)", None)
    if not (np.isfinite(rec) and np.isfinite(new)):
        return _row(quantity, rec, new, accuracy, rule, bool(rec == new))
    return _row(quantity, rec, new, float(accuracy), rule, bool(abs(rec - new) <= accuracy))


def _level(dH, s) -> float:
    """``max_w sigma_max(dH(w)) / s(w)`` over the frequencies where ``s > 0`` (0 where none)."""
    d = sigma_max(dH)
    ok = s > 0
    return float(np.max(d[ok] / s[ok])) if np.any(ok) else 0.0


def _band_rows(fom, rom, band) -> tuple[list, int]:
    omega = grid_omega(band["grid"])
    _, lus = band_response(fom, omega)  # the LUs; the LU's and the refined values kept in the model's memo
    ev = FomResponse(fom, refine=1, memo=True)
    samples = [ev.sample(1j * w) for w in omega]
    H0 = np.stack([np.asarray(t[0], dtype=complex) for t in samples])  # the LU's values
    T = np.stack([np.asarray(t[1], dtype=complex) for t in samples])
    rr = RomResponse(*first_order_arrays(fom, rom), refine=1)
    Tr = np.stack([np.asarray(rr.transfer(1j * w), dtype=complex) for w in omega])
    df = errors(fom, rom, omega, H_full=T)
    Hr = rom.freqresp(omega)
    sf, sr = sigma_max(T), sigma_max(Tr)
    # the LU values' relative error level over the grid (another run's errors, frequency by frequency, differ
    # by orders of magnitude where one is small by chance; their levels by a factor below 2: romfiles.md)
    level_full, level_rom = _level(H0 - T, sf), _level(Hr - Tr, sr)
    acc_peak = (LU_FACTOR * level_full + ROUNDING * EPS) * sf
    acc = acc_peak + (LU_FACTOR * level_rom + ROUNDING * EPS) * sr
    rel = df["rel_error"].to_numpy()
    with np.errstate(divide="ignore", invalid="ignore"):
        acc_rel = np.where(sf > acc, acc * (1 + rel) / (sf - acc), np.inf)
    rule = f"|difference| <= ({LU_FACTOR:g} x the LU values' error level + {ROUNDING:g} eps) x sigma_max"
    rows = [_within("band max error", _num(band.get("max_abs_error")), float(df["abs_error"].max()),
                    float(acc.max()), rule),
            _within("band peak", _num(band.get("peak")), float(sf.max()), float(acc_peak.max()), rule),
            _within("band max relative error", _num(band.get("max_rel_error")), float(rel.max()),
                    float(acc_rel.max()), rule + ", divided by sigma_max(T)")]
    return rows, lus


def _h2_rows(rec, new):
    rows = []
    for quantity, key, fkey, nkey, nfkey in (("H2 error", "error", "floor", "h2_error", "h2_floor"),
                                             ("H2 norm", "norm", "norm_floor", "h2_norm", "h2_norm_floor")):
        a, b = _num(rec.get(key)), _num(new.get(nkey))
        fa, fb = _num(rec.get(fkey)), _num(new.get(nfkey))
        acc = None if fa is None or fb is None or a is None or b is None else \
            fa + fb + ROUNDING * EPS * (abs(a) + abs(b))
        row = _within(quantity, a, b, acc, f"|difference| <= the two floors + {ROUNDING:g} eps")
        row.update(recorded_floor=fa, recomputed_floor=fb)
        rows.append(row)
    return rows


def _enclosure(quantity, lo_a, up_a, lo_b, up_b, rtol):
    """Compare two H-infinity values given as (lower, upper or None)."""
    if lo_a is None or lo_b is None:
        return _row(quantity, lo_a, lo_b, None, "not recorded" if lo_a is None else "not computed", None,
                    recorded_upper=up_a, recomputed_upper=up_b)
    slack = ROUNDING * EPS * (abs(lo_a) + abs(lo_b))
    extra = {"recorded_upper": up_a, "recomputed_upper": up_b}
    if not (np.isfinite(lo_a) and np.isfinite(lo_b)):
        return _row(quantity, lo_a, lo_b, None, "infinite (unstable reduced model)", bool(lo_a == lo_b), **extra)
    if up_a is not None and up_b is not None:
        ok = lo_a <= up_b + slack and lo_b <= up_a + slack
        return _row(quantity, lo_a, lo_b, max(up_a - lo_a, up_b - lo_b), "certified enclosures overlap", ok, **extra)
    if up_a is not None or up_b is not None:
        lower, upper = (lo_b, up_a) if up_a is not None else (lo_a, up_b)
        return _row(quantity, lo_a, lo_b, upper - min(lo_a, lo_b), "lower bound <= certified upper bound",
                    bool(lower <= upper + slack), **extra)
    acc = rtol * max(abs(lo_a), abs(lo_b)) + slack
    return _row(quantity, lo_a, lo_b, acc, f"lower bounds only: the same peak to rtol {rtol:g}",
                bool(abs(lo_a - lo_b) <= acc), **extra)


def _hinf_rows(rec, new):
    rtol = _num((rec.get("options") or {}).get("rtol")) or 1e-10
    up = (lambda x, c: _num(x) if c else None)
    return [_enclosure("Hinf error", _num(rec.get("lower_bound")), up(rec.get("upper_bound"), rec.get("certified")),
                       _num(new.get("hinf_error")), up(new.get("hinf_upper_bound"), new.get("hinf_certified")), rtol),
            _enclosure("Hinf norm", _num(rec.get("norm")), up(rec.get("norm_upper_bound"), rec.get("norm_certified")),
                       _num(new.get("hinf_norm")), up(new.get("hinf_norm_upper_bound"), new.get("hinf_norm_certified")),
                       rtol)]


def _options(rec):
    """Recorded norm options, the strings the sidecar writes for non-finite numbers turned back."""
    out = {}
    for k, v in (rec or {}).items():
        out[k] = float(v) if isinstance(v, str) and v in ("inf", "-inf", "nan") else v
    return out


def verify_rom(fom, rom, record=None, *, norms: bool = True) -> dict:
    r"""Compute again the errors a reduced model's sidecar recorded and compare them within their accuracy.

    Parameters
    ----------
    fom : Index3Model
        The model the reduced model was made from.
    rom : SecondOrderROM or FirstOrderROM
        Read by :func:`morsuite.load_rom` (its ``provenance`` is the sidecar).
    record : dict, optional
        The sidecar (default ``rom.provenance``).
    norms : bool
        Also compute the H2 and H-infinity errors again (default True; they cost the model's
        Gramian factors and up to a few hundred LUs); False: their rows are not judged.

    Returns
    -------
    dict
        ``agrees`` (every judged row agrees and the model's hash is the recorded one),
        ``failed`` (the quantities that do not agree), ``rows`` (``quantity``, ``recorded``,
        ``recomputed``, ``accuracy`` (the allowed difference), ``rule``, ``agrees``: True,
        False or None for not judged; H2 rows add both floors, H-infinity rows both upper
        bounds), ``model_hash`` (``recorded``, ``computed``, ``equal``), ``lu_count`` (of the
        band response), ``norm_warnings``, ``time_s``. The rules: module docstring.

    Raises
    ------
    InputError
        No sidecar (nothing recorded to verify), or one without provenance.

    Notes
    -----
    Cost: one LU per grid frequency (two threads, :func:`~morsuite.analysis.band_response`)
    with one refinement step; with ``norms``, :func:`~morsuite.analysis.error_norms` (the
    Gramian factors once per model, then up to about ``max_lus`` LUs).
    """
    t0 = time.perf_counter()
    record = getattr(rom, "provenance", None) if record is None else record
    if not isinstance(record, dict):
        raise InputError("rom has no sidecar (STEM.json): nothing recorded to verify; save it with "
                         "morsuite.romfiles.save_rom or `morsuite reduce --save`")
    prov = record.get("provenance")
    if not isinstance(prov, dict):
        raise InputError("the sidecar has no provenance (written by rom.save or save_rom without one): "
                         "nothing recorded to verify")
    recorded = (prov.get("model") or {}).get("hash")
    computed = model_hash(fom)
    same = recorded == computed
    rows = [_row("model hash", recorded, computed, None, "equal", same)]
    if not same:
        warnings.warn(f"the model's hash {computed[:16]}... differs from the recorded {str(recorded)[:16]}... "
                      f"({(prov.get('model') or {}).get('source') or (prov.get('model') or {}).get('name')}): "
                      "another model; the verification fails", AccuracyWarning, stacklevel=2)
    out = {"model_hash": {"recorded": recorded, "computed": computed, "equal": same}, "lu_count": 0,
           "norm_warnings": []}
    errs = prov.get("errors") or {}
    if (rom.m, rom.p) != (fom.m, fom.p):
        rows.append(_row("inputs and outputs", [rom.m, rom.p], [fom.m, fom.p], None, "equal", False))
    else:
        if errs.get("band"):
            band_rows, out["lu_count"] = _band_rows(fom, rom, errs["band"])
            rows += band_rows
        kinds = [k for k in ("h2", "hinf") if errs.get(k)]
        new = {}
        if norms and kinds:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # recorded in norm_warnings
                new = error_norms(fom, rom, kinds, {k: _options(errs[k].get("options")) for k in kinds})
            out["norm_warnings"] = new.get("norm_warnings", [])
        for kind, make in (("h2", _h2_rows), ("hinf", _hinf_rows)):
            if not errs.get(kind):
                rows.append(_row(f"{'H2' if kind == 'h2' else 'Hinf'} error", None, None, None,
                                 f"not recorded ({errs.get('norms') or 'no value'})", None))
            elif not norms:
                rows += [{**r, "recomputed": None, "accuracy": None, "rule": "not recomputed (--no-norms)",
                          "agrees": None} for r in make(errs[kind], {})]
            else:
                rows += make(errs[kind], new)
    failed = [r["quantity"] for r in rows if r["agrees"] is False]
    return {"agrees": not failed, "failed": failed, "rows": rows, **out, "time_s": time.perf_counter() - t0}


def _fmt(x):
    if x is None:
        return "-"
    if isinstance(x, str):
        return x[:16] + ("..." if len(x) > 16 else "")
    if isinstance(x, (list, tuple)):
        return ", ".join(_fmt(v) for v in x)
    return f"{x:.6e}" if isinstance(x, float) else str(x)


def table_lines(result: dict) -> list[str]:
    """The rows of :func:`verify_rom` as a text table (quantity, recorded, recomputed, accuracy, agrees,
    rule), then a verdict line."""
    head = ("quantity", "recorded", "recomputed", "accuracy", "agrees", "rule")
    cells = [head] + [(r["quantity"], _fmt(r["recorded"]), _fmt(r["recomputed"]), _fmt(r["accuracy"]),
                       {True: "yes", False: "NO", None: "-"}[r["agrees"]], r["rule"]) for r in result["rows"]]
    width = [max(len(c[i]) for c in cells) for i in range(len(head))]
    lines = ["  ".join(c[i].ljust(width[i]) for i in range(len(head))).rstrip() for c in cells]
    lines.append("verified: every recorded value agrees" if result["agrees"] else
                 "NOT verified: " + ", ".join(result["failed"]) + " disagree")
    return lines
