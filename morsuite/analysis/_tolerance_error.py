r"""What a tolerance search's errors are relative to, and the relative error of one reduced model.

:class:`Reference` holds, for one model and error measure (:data:`morsuite.analysis.tolerance.MEASURES`),
the scale a tolerance is relative to and what the error needs: the full response on the band's
grid (``"band"``: computed once, one LU per frequency, or given), or the model's H2 / Hinf norm
record (:func:`~morsuite.analysis.compare.model_norm`). :meth:`Reference.error` gives a reduced
model's relative error with its floor and whether it is trusted. A proxy search shares its
caller's reference.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from ..errors import InputError

__all__ = ["BAND_FLOOR", "Reference"]

#: relative level below which a sampled band error is not trusted: the refined full response and the
#: dense reduced one carry rounding of about this relative size (an estimate, docs/design/tolerance.md)
BAND_FLOOR = 1e-12


class Reference:
    """The reference of a tolerance search (module docstring): ``scale``, ``omega`` and ``H_full`` (band),
    ``model_norm`` (H2, Hinf), and what computing it cost (``lus``, ``time_s``)."""

    def __init__(self, fom, measure: str, *, omega=None, H_full=None, norm_options=None):
        from .compare import model_norm
        from .response import band_response, freq_grid, sigma_max

        self.fom, self.measure, self.norm_options = fom, measure, dict(norm_options or {})
        self.omega = self.H_full = self.model_norm = None
        self.lus, t0 = 0, time.perf_counter()
        if measure == "band":
            self.omega = freq_grid(fom.band) if omega is None else np.asarray(omega, dtype=float).ravel()
            if H_full is None:
                H_full, self.lus = band_response(fom, self.omega)
            self.H_full = np.asarray(H_full)
            if self.H_full.shape != (self.omega.size, fom.p, fom.m):
                raise InputError(f"H_full has shape {self.H_full.shape}; expected "
                                 f"{(self.omega.size, fom.p, fom.m)} (omega, p, m)")
            self.scale = float(np.max(sigma_max(self.H_full)))
        else:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # recorded in the norm's record
                self.model_norm = model_norm(fom, measure, self.norm_options.get(measure))
            self.scale = float(self.model_norm["value"])
            self.lus = int(self.model_norm["lu_count"])
        self.time_s = time.perf_counter() - t0
        if not (self.scale > 0 and np.isfinite(self.scale)):
            raise InputError(f"the full model's {measure} scale is {self.scale!r}: a relative tolerance needs a "
                             "positive finite norm")

    def error(self, rom) -> dict:
        """``{"value", "floor", "trusted", "lus", "record"}``: the relative error of ``rom`` (band: the grid's
        maximum over the band peak; H2: exact with its floor; Hinf: the certified upper bound, else the peak
        found, untrusted), its floor (relative), trust, the LUs it cost and the record behind it."""
        from .compare import error_norm
        from .response import sigma_max

        if self.measure == "band":
            e = sigma_max(self.H_full - rom.freqresp(self.omega))
            k = int(np.argmax(e))
            value = float(e[k]) / self.scale
            return {"value": value, "floor": BAND_FLOOR, "trusted": bool(np.isfinite(value) and value > BAND_FLOOR),
                    "lus": 0, "record": {"max_abs_error": float(e[k]), "omega_max": float(self.omega[k]),
                                         "grid": [float(self.omega[0]), float(self.omega[-1]), int(self.omega.size)]}}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # recorded in the record's warnings
            rec = error_norm(self.fom, rom, self.measure, self.norm_options.get(self.measure))
        keep = {k: rec.get(k) for k in ("value", "route", "floor", "trusted", "lower_bound", "upper_bound",
                                        "certified", "peak_frequency", "reason") if k in rec}
        if self.measure == "h2":
            value = rec["value"] / self.scale
            floor = (rec.get("floor") or 0.0) / self.scale
            trusted = bool(rec.get("trusted")) and bool(self.model_norm.get("trusted"))
        else:
            certified = bool(rec.get("certified")) and rec.get("upper_bound") is not None
            value = (rec["upper_bound"] if certified else rec["value"]) / self.scale
            floor, trusted = 0.0, certified  # the upper bound is the value: nothing to add
        return {"value": float(value), "floor": float(floor), "trusted": trusted, "lus": int(rec.get("lu_count") or 0),
                "record": keep}
