"""The ``loewner`` reducer: options, the samples of T(jw) through the model's memo, the record."""

from __future__ import annotations

import time

import numpy as np

from ...errors import InputError, RankWarning, StabilityWarning
from ...rom import FirstOrderROM
from ...utils import band_pair, default_threads, map_threads
from ..base import Option, Reducer
from ..cost import cost_record
from ..registry import Description
from .pencil import conjugate_points, loewner_pencil, project, real_form, truncation_bases

__all__ = ["Loewner", "sample_frequencies"]

def sample_frequencies(band, samples: int) -> np.ndarray:
    """``samples`` log-spaced frequencies on ``band`` (rad/s): the formula of a study's grid
    (:meth:`morsuite.studies.spec.GridEntry.frequencies`), so the same floats, the same memo keys."""
    lo, hi = band
    return np.logspace(np.log10(lo), np.log10(hi), samples)


class Loewner(Reducer):
    """Data-driven reduction from samples of T(jw) on the band (module docstring of the package).

    ``reduce(r)`` returns a :class:`~morsuite.rom.FirstOrderROM` (descriptor E, A, B, C) with r
    states, fewer where the Loewner pencil's numerical rank (``rank_tol``) is below r.
    """

    name = "loewner"
    DESCRIPTION = Description(
        label="Loewner (data-driven, from the band samples)", result="first-order",
        targets="interpolation of T(jw) samples on the band, truncated by the Loewner singular values",
        cost="one per sample (none where the band response is in the model's memo)",
        use_for="a model from the frequency response alone, every r from one set of samples",
        options=("band", "samples", "omega", "rank_tol"), band_option="band", page="loewner", order=100)

    OPTIONS = {
        "band": Option(None, "any", "frequency band (w1, w2) in rad/s, 0 < w1 < w2, of the samples; None: the "
                       "model's band (fom.band)", nullable=True),
        "samples": Option(200, "int", "log-spaced frequencies sampled on the band (200: the grid of a "
                          "comparison's band response, whose memo serves them)", low=2),
        "omega": Option(None, "array", "the sampled frequencies (rad/s, > 0, distinct) instead of band and samples",
                        nullable=True),
        "partition": Option("alternating", "choice", "which samples are left and right points: alternating in "
                            "frequency, or the lower and the upper half", choices=("alternating", "halves")),
        "rank_tol": Option(1e-12, "float", "singular values of the Loewner pencil below rank_tol times the largest "
                           "are never kept (caps r)", low=0, high=1, open_high=True),
        "refined": Option(True, "bool", "the samples' extended-precision refined values (no extra LU) or the "
                          "LU's values"),
        "solver_threads": Option(0, "int", "threads that factor and solve the samples concurrently (0: 2 on two or "
                                 "more cores, 1 for KLU)", low=0),
    }

    def __init__(self, fom, **options):
        super().__init__(fom, **options)
        self._data = None  # the samples and the pencil's real form and SVDs: r-independent, kept

    def _check_options(self):
        o = self.options
        if o["omega"] is not None:
            w = np.asarray(o["omega"], dtype=float).ravel()
            if np.iscomplexobj(o["omega"]) or w.size < 2 or np.any(w <= 0) or np.unique(w).size != w.size:
                raise InputError(f"The 'omega' parameter of Loewner must hold at least 2 distinct real frequencies "
                                 f"> 0 (rad/s); got {o['omega']!r}")
            o["omega"] = np.sort(w)
        else:
            o["band"] = band_pair(self.fom.band if o["band"] is None else o["band"],
                                  name="The 'band' parameter of Loewner")

    def _frequencies(self) -> np.ndarray:
        o = self.options
        return o["omega"] if o["omega"] is not None else sample_frequencies(o["band"], o["samples"])

    def _split(self, n):
        """Indices of the left and right frequencies."""
        idx = np.arange(n)
        if self.options["partition"] == "alternating":
            return idx[0::2], idx[1::2]
        return idx[: (n + 1) // 2], idx[(n + 1) // 2:]

    def max_order(self) -> int:
        """Largest admissible r: the pencil's smaller dimension (2 p per left frequency, 2 m per right one),
        at most the model's 2 (n1 - n2) first-order states."""
        left, right = self._split(self._frequencies().size)
        return min(2 * left.size * self.fom.p, 2 * right.size * self.fom.m, 2 * self.fom.order)

    # -- the samples --------------------------------------------------------
    def _sample(self, omega):
        r""":math:`T(j\omega_k)` (len(omega), p, m) and the LUs paid: through the model's memo of
        :math:`T(j\omega)` (:class:`~morsuite.norms._fom.FomResponse`, as
        :func:`morsuite.analysis.band_response` fills it), one LU per frequency not kept yet, dealt out to
        ``solver_threads`` threads (each sample depends on its frequency only)."""
        from ...norms._fom import FomResponse

        ev = FomResponse(self.fom, refine=1, memo=True)
        threads = min(self.options["solver_threads"] or default_threads(ev.solver.backend), omega.size)
        evs = [ev] + [FomResponse(self.fom, refine=1, memo=True) for _ in range(threads - 1)]
        out = np.empty((omega.size, self.fom.p, self.fom.m), dtype=complex)
        refined = self.options["refined"]

        def run(k):
            for i in range(k, omega.size, threads):
                T0, T, _ = evs[k].sample(1j * omega[i])
                out[i] = np.asarray(T if refined and T is not None else T0, dtype=complex)
        map_threads(run, list(range(threads)), threads)
        return out, sum(e.lu_count for e in evs)

    def _setup(self):
        """The r-independent work, once per reducer: samples, pencil, real form, SVDs (timed by parts)."""
        omega = self._frequencies()
        t0 = time.perf_counter()
        H, lus = self._sample(omega)
        t1 = time.perf_counter()
        left, right = self._split(omega.size)
        lam, Hl = conjugate_points(omega[left], H[left])
        mu, Hr = conjugate_points(omega[right], H[right])
        L, Ls, V, W, imag = real_form(*loewner_pencil(lam, Hl, mu, Hr), self.fom.p, self.fom.m)
        t2 = time.perf_counter()
        Y, s_row, X, s_col = truncation_bases(L, Ls)
        t3 = time.perf_counter()
        # what the samples cost whoever paid them: the memo keeps each one's seconds (None if one is missing)
        kept = self.fom.cache.get(("fom_response_seconds", 1), {})
        seconds = [kept.get(complex(1j * w)) for w in omega]
        unpaid = None if any(x is None for x in seconds) else float(sum(seconds))
        self._data = {"omega": omega, "H": H, "lus": lus, "pencil": (L, Ls, V, W), "imag": imag,
                      "bases": (Y, X), "sv": (s_row, s_col),
                      "paid": {"samples": t1 - t0, "pencil": t2 - t1, "svd": t3 - t2},
                      "cost": {"samples": (t1 - t0) if lus == omega.size else unpaid,
                               "pencil": t2 - t1, "svd": t3 - t2}}
        return self._data

    # -- reduction ----------------------------------------------------------
    def _reduce(self, r):
        fresh = self._data is None
        d = self._data or self._setup()
        s_row, s_col = d["sv"]
        if not s_row[0] > 0:
            raise InputError(f"loewner: the sampled transfer function of {self.fom.name} vanishes at every "
                             "frequency: nothing to reduce")
        tol = self.options["rank_tol"]
        rank = int(min(np.sum(s_row > tol * s_row[0]), np.sum(s_col > tol * s_col[0])))
        k = min(r, rank)
        if k < r:
            self.warn(f"loewner: the Loewner pencil of {d['omega'].size} samples has numerical rank {rank} at "
                      f"rank_tol = {tol:g}; r capped from {r} to {k}", RankWarning)
        t0 = time.perf_counter()
        E, A, B, C = project(*d["pencil"], *d["bases"], k)
        rom = FirstOrderROM(E, A, B, C)
        t_proj = time.perf_counter() - t0
        stable = bool(rom.is_stable())
        if not stable:
            self.warn(f"loewner: the reduced model at r = {k} has poles in the closed right half-plane (the "
                      "Loewner framework does not preserve stability)", StabilityWarning)
        n, lus = d["omega"].size, d["lus"]
        paid = d["paid"] if fresh else {"samples": 0.0, "pencil": 0.0, "svd": 0.0}
        cost = {key: v for key, v in d["cost"].items() if v is not None}
        info = {
            "status": "direct", "samples": int(n), "omega": d["omega"], "band": [float(d["omega"][0]),
                                                                                 float(d["omega"][-1])],
            "singular_values": (s_row / s_row[0])[: min(s_row.size, 2 * k + 10)],
            "rank": rank, "rank_capped": bool(k < r), "imag_dropped": d["imag"], "stable": stable,
            "samples_from_memo": int(n - lus),
            "setup_cost_unknown": [key for key, v in d["cost"].items() if v is None],
            # one LU per sample (a conjugate point is free), whoever paid it; a call that did not pay every
            # sample reused them: studies add the unpaid cost back for standalone times
            **cost_record(lus_shared=n, lus_paid=lus if fresh else 0, setup_cost=cost, paid=paid,
                          breakdown={"projection": t_proj}),
        }
        return rom, info
