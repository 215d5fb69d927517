r"""Floors: what a run's sparse LUs cost bare, measured in the same process as the run.

The unit is one sparse LU of the saddle-point matrix

.. math::

    S(s) = \begin{bmatrix} s^2 M + s D + K & G^T \\ G & 0 \end{bmatrix}

with its solves: ``scipy.sparse.linalg.splu`` of the pre-assembled, unscaled
:math:`S(s)` with the column ordering and pivot threshold of
``fom.new_solver()`` (:func:`bare_splu`); assembly is not timed. A run that made
N LUs is judged by ``time / floor``, the floor being N such LUs at the run's own
shifts. Run and floor are timed back to back, and repeated alternately, so that
the load of a shared machine hits both alike (:func:`run_against_floor`,
:func:`median_run`).

- :func:`bare_lu_floor`: the mean over the shifts of one LU with a right solve
  with :math:`[F; 0]` and a transposed solve with :math:`[L^T; 0]`, times N
  (benchmarks ``irka`` and ``bt``).
- :func:`lu_floor`: the median of one LU with right and transposed solves of given
  widths at up to ``samples`` shifts, ``repeat`` times each, and the same through
  the solver (benchmark ``pareto``).
- :func:`irka_lu_shifts`, :func:`adi_lu_shifts`, :func:`upper_half`: the shifts at
  which a run factorized, read from its ``info``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..utils import blas_threads

__all__ = ["bare_splu", "bare_lu_floor", "lu_floor", "upper_half", "irka_lu_shifts", "adi_lu_shifts",
           "FloorRun", "run_against_floor", "median_run"]


def bare_splu(solver, A, permc_spec=None):
    """The floor's LU: ``splu(A)`` with ``solver``'s ordering (or ``permc_spec``) and pivot threshold."""
    import scipy.sparse.linalg as spla

    return spla.splu(A, permc_spec=permc_spec or solver.permc_spec, diag_pivot_thresh=solver.diag_pivot_thresh)


def bare_lu_floor(fom, shifts, n_lu: int) -> float:
    """Seconds of ``n_lu`` bare LUs + 2 solves, measured at ``shifts`` (assembly not timed).

    If the shifts are fewer or more than ``n_lu`` (a perturbed or refactored shift),
    the mean per shift is scaled to ``n_lu``. Cost: one LU per shift.
    """
    solver = fom.new_solver(cache_size=0)
    rhs_r = np.vstack([fom.F, np.zeros((fom.n2, fom.m))])
    rhs_l = np.vstack([fom.L.T, np.zeros((fom.n2, fom.p))])
    total = 0.0
    for a in shifts:
        A = solver.matrix(a)
        t0 = time.perf_counter()
        lu = bare_splu(solver, A)
        lu.solve(rhs_r.astype(A.dtype, copy=False))
        lu.solve(rhs_l.astype(A.dtype, copy=False), trans="T")
        total += time.perf_counter() - t0
    return total / max(len(shifts), 1) * n_lu


def lu_floor(fom, shifts, widths=(1, 1), samples: int = 8, repeat: int = 3) -> dict:
    """Median seconds of one sparse LU of the saddle matrix plus a right and a transposed solve.

    ``splu`` of the pre-assembled matrix with the options of
    ``fom.new_solver()`` (ordering, pivot threshold), at up to ``samples``
    of ``shifts`` (evenly chosen) ``repeat`` times each, alternating, with
    ``widths`` = (right, transposed) right-hand-side columns and one BLAS
    thread. Also the same through :meth:`SaddlePointSolver.factor` (assembly
    and solve checks included): ``solver_median_s``. Cost: 2 x ``samples`` x
    ``repeat`` LUs.
    """
    shifts = np.asarray(shifts, dtype=complex).ravel()
    if shifts.size == 0:
        raise InputError("lu_floor: 'shifts' is empty; it needs at least one shift")
    idx = np.unique(np.linspace(0, shifts.size - 1, min(samples, shifts.size)).round().astype(int))
    sample = [complex(s) for s in shifts[idx]]
    solver = fom.new_solver(cache_size=0)
    n = fom.n1 + fom.n2
    raw, via = [], []
    with blas_threads(1):
        for k in range(repeat):
            for s in (sample if k % 2 == 0 else sample[::-1]):
                s_ = s if s.imag != 0 else s.real
                A = solver.matrix(s_)
                dt = np.complex128 if np.iscomplexobj(A.data) else np.float64
                br = np.zeros((n, widths[0]), dtype=dt)
                br[: fom.n1] = (fom.F @ np.ones((fom.m, widths[0]))) if widths[0] <= fom.m else 1.0
                bl = np.zeros((n, widths[1]), dtype=dt)
                bl[: fom.n1] = (fom.L.T @ np.ones((fom.p, widths[1]))) if widths[1] <= fom.p else 1.0
                t0 = time.perf_counter()
                lu = bare_splu(solver, A)
                lu.solve(br)
                lu.solve(bl, trans="T")
                raw.append(time.perf_counter() - t0)
                del lu
                t0 = time.perf_counter()
                f = solver.factor(s_)
                f.solve(br[: fom.n1])
                f.solve(bl[: fom.n1], trans=True)
                via.append(time.perf_counter() - t0)
    return {"median_s": float(np.median(raw)), "solver_median_s": float(np.median(via)),
            "samples": len(raw), "shifts_sampled": [[s.real, s.imag] for s in sample],
            "definition": f"splu(S(s), permc_spec={solver.permc_spec}, diag_pivot_thresh="
                          f"{solver.diag_pivot_thresh}) + solve with {widths[0]} and transposed solve with "
                          f"{widths[1]} columns, S pre-assembled; median over {len(raw)}"}


# ---------------------------------------------------------------------------
# the shifts at which a run factorized
# ---------------------------------------------------------------------------

def upper_half(shifts) -> np.ndarray:
    """One shift per LU: real data factorize once per real shift or conjugate pair (``imag >= 0``)."""
    from ..reducers.base import as_complex

    s = as_complex(shifts)
    return s[s.imag >= 0]


def irka_lu_shifts(info) -> list:
    """IRKA's LUs: per iteration of ``info["history"]["shifts"]``, one per real shift or conjugate pair."""
    out = []
    for sh in info["history"]["shifts"]:
        out.extend(upper_half(sh))
    return out


def adi_lu_shifts(info) -> np.ndarray:
    """BT's LUs: the LU of :math:`S(-p)` per controllability ADI shift :math:`p` (it serves both
    Gramians), one per real shift or conjugate pair."""
    return -upper_half(info["adi"]["controllability"]["shifts"])


# ---------------------------------------------------------------------------
# a run and its floor, back to back
# ---------------------------------------------------------------------------

@dataclass
class FloorRun:
    """One timed run and the bare floor of its LUs, measured right after it."""

    time_s: float
    floor_s: float
    info: dict

    @property
    def ratio(self) -> float:
        """The run's time over its floor (1: the run costs what its LUs cost bare)."""
        return self.time_s / self.floor_s


def run_against_floor(fom, run, shifts_of, *, threads: int = 1) -> FloorRun:
    """Time ``run() -> (seconds, info)``, then :func:`bare_lu_floor` of its ``info["lu_count"]``
    LUs at ``shifts_of(info)`` with BLAS limited to ``threads``."""
    seconds, info = run()
    with blas_threads(threads):
        floor = bare_lu_floor(fom, shifts_of(info), info["lu_count"])
    return FloorRun(float(seconds), floor, info)


def median_run(runs) -> FloorRun:
    """The run of median ratio (the upper of the two middle ones for an even count)."""
    return sorted(runs, key=lambda r: r.ratio)[len(runs) // 2]
