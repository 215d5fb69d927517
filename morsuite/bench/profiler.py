"""Where a run's time goes: a profiler that charges time by call stack to named categories.

cProfile charges each function's own time but cannot say under which caller it ran.
:class:`StackProfiler` (``sys.setprofile``) charges every interval between two profile
events to the highest-priority category of :data:`CATEGORIES` with a function on the
call stack, or to :data:`REST` (Python overhead), so that e.g. a QR inside ``orth``
counts as orthogonalisation and the SuperLU factorization inside a saddle-solver call
as sparse LU. :func:`profile_categories` runs a function under it and under cProfile.
Profiling slows Python-heavy code more than SuperLU: shares are of the profiled run.
"""

from __future__ import annotations

import cProfile
import pstats
import time
from pathlib import Path

__all__ = ["CATEGORIES", "REST", "StackProfiler", "profile_categories"]


#: profile categories in priority order: an instant of the run counts for the first category
#: that has a function on the call stack (so the SuperLU factorization inside a saddle
#: solver call counts as "sparse LU", a QR inside ``orth`` as orthogonalisation).
#: (group, category, matchers); a matcher is ("builtin", substring of "module.name" of a
#: C function, or "Type.name" for a method) or (path substring, function name or "*").
CATEGORIES = [
    ("floor", "sparse LU (SuperLU gstrf)", [("builtin", "_superlu.gstrf")]),
    ("floor", "sparse triangular solves (SuperLU)", [("builtin", "SuperLU.solve")]),
    ("sparse overhead", "saddle matrix assembly and equilibration (one pass)",
     [("linalg/saddle.py", "matrix"), ("linalg/saddle.py", "_coeffs"), ("linalg/saddle.py", "_build_pattern"),
      ("linalg/saddle.py", "_assemble_scaled"), ("linalg/saddle.py", "_diagonal_scaling"),
      ("linalg/saddle.py", "_csc")]),
    ("sparse overhead", "solve accuracy checks (backward error, refinement, condition estimate)",
     [("linalg/saddle_lu.py", "_checked"), ("linalg/saddle_lu.py", "_backward_error"), ("linalg/saddle_lu.py", "_apply"),
      ("linalg/saddle_lu.py", "rcond_estimate"), ("linalg/refine.py", "*")]),
    ("sparse overhead", "Ruiz equilibration",
     [("linalg/saddle.py", "_ruiz")]),
    ("sparse overhead", "SuperLU wrappers and saddle solver bookkeeping (norms, conversions)",
     [("linalg/saddle.py", "*"), ("linalg/saddle_lu.py", "*"), ("sparse/linalg/_dsolve/", "*")]),
    ("orthogonalisation", "orthogonalisation (QR/SVD of n1 x k bases)",
     [("linalg/dense.py", "orth"), ("reducers/bt/balanced.py", "_orthonormal"), ("linalg/adi_shifts.py", "_orthonormal_map"),
      ("linalg/orthonormal.py", "*")]),
    ("dense work", "projection onto the bases (n1 x k products)",
     [("reducers/irka/engine.py", "_project"),
      ("reducers/bt/balanced.py", "_first_order"), ("reducers/bt/balanced.py", "_second_order")]),
    ("dense work", "ADI shift computation (Ritz values)",
     [("linalg/adi_shifts.py", "projection_shifts"), ("linalg/adi_shifts.py", "penzl_shifts"),
      ("linalg/adi_shifts.py", "select_shifts")]),
    ("dense work", "ADI vector updates, residual and factor (n1 x k)",
     [("linalg/adi_iteration.py", "step"), ("linalg/adi_iteration.py", "take_block"), ("linalg/adi_iteration.py", "factor"),
      ("linalg/adi_iteration.py", "_append"), ("linalg/adi_iteration.py", "_update"), ("linalg/adi_iteration.py", "_norm2"),
      ("linalg/manifold.py", "__call__"), ("linalg/manifold.py", "project")]),
    ("dense work", "dense r-sized work (shift update, poles, reduced responses, small SVDs)",
     [("reducers/irka/engine.py", "_update"), ("reducers/irka/shift_update.py", "*"), ("morsuite/rom.py", "*"), ("linalg/dense.py", "*"),
      ("reducers/bt/balanced.py", "_svd"), ("reducers/bt/balanced.py", "_cap"), ("analysis/response.py", "*"),
      ("numpy/linalg/", "*"), ("scipy/linalg/", "*"), ("builtin", "numpy.linalg"), ("builtin", "scipy.linalg")]),
    ("sparse overhead", "sparse-matrix products and conversions (scipy.sparse)",
     [("scipy/sparse/", "*"), ("builtin", "scipy.sparse")]),
    ("dense work", "other NumPy array functions (copies, stacking, reductions)",
     [("numpy/", "*"), ("builtin", "numpy."), ("builtin", "ndarray."), ("builtin", "ufunc.")]),
]
REST = ("Python overhead (interpreter; inline NumPy operators such as @ and + in Python code "
        "outside the categories above)")


class StackProfiler:
    """A deterministic profiler (``sys.setprofile``) that charges time to categories by call stack.

    cProfile charges each function's own time but cannot say under which caller it ran;
    here every interval between two profile events goes to the highest-priority category
    with a function on the stack (``CATEGORIES``), or to ``REST``. The time spent in the
    profile callback itself is excluded from every category.
    """

    def __init__(self, categories=None):
        self.categories = list(categories or CATEGORIES)
        self.n = len(self.categories)
        self.times = [0.0] * (self.n + 1)
        self._code = {}
        self._c = {}
        self.stack = [self.n]
        self.last = 0.0
        self.events = 0

    def _match(self, kind, text, name):
        for i, (_, _, matchers) in enumerate(self.categories):
            for path, func in matchers:
                if kind == "c" and path == "builtin" and func in text:
                    return i
                if kind == "py" and path != "builtin" and path in text and (func == "*" or func == name):
                    return i
        return self.n

    def _code_cat(self, code):
        c = self._code.get(code)
        if c is None:
            c = self._code[code] = self._match("py", code.co_filename.replace("\\", "/"), code.co_name)
        return c

    def _c_cat(self, func):
        mod = getattr(func, "__module__", None)
        owner = mod or type(getattr(func, "__self__", None)).__name__
        desc = f"{owner}.{getattr(func, '__name__', '?')}"
        c = self._c.get(desc)
        if c is None:
            c = self._c[desc] = self._match("c", desc, None)
        return c

    def __call__(self, frame, event, arg):
        now = time.perf_counter()
        st = self.stack
        self.times[st[-1]] += now - self.last
        self.events += 1
        if event == "call":
            st.append(min(st[-1], self._code_cat(frame.f_code)))
        elif event == "c_call":
            st.append(min(st[-1], self._c_cat(arg)))
        elif len(st) > 1:  # return, c_return, c_exception
            st.pop()
        self.last = time.perf_counter()

    def run(self, fn, *args, **kwargs):
        """Call ``fn(*args, **kwargs)`` under the profiler and return its result."""
        import sys

        self.last = time.perf_counter()
        sys.setprofile(self)
        try:
            return fn(*args, **kwargs)
        finally:
            sys.setprofile(None)

    def summary(self) -> dict:
        """Seconds per category and per group (plain data)."""
        cats, groups = {}, {}
        for (group, name, _), t in zip(self.categories, self.times):
            cats[name] = t
            groups[group] = groups.get(group, 0.0) + t
        cats[REST] = self.times[self.n]
        groups["Python overhead"] = self.times[self.n]
        return {"total_s": float(sum(self.times)), "categories_s": cats, "groups_s": groups,
                "events": self.events}


def profile_categories(fn, *args, top: int = 10, **kwargs) -> tuple:
    """Run ``fn`` twice: under :class:`StackProfiler` (time per category) and under cProfile
    (the ``top`` functions by own time). Returns (fn's result of the first run, summary)."""
    prof = StackProfiler()
    t0 = time.perf_counter()
    out = prof.run(fn, *args, **kwargs)
    wall = time.perf_counter() - t0
    summ = prof.summary()
    summ["wall_s"] = wall
    cp = cProfile.Profile()
    cp.enable()
    try:
        fn(*args, **kwargs)
    finally:
        cp.disable()
    st = pstats.Stats(cp)
    rows = sorted(((v[2], v[3], v[1], k) for k, v in st.stats.items()), reverse=True)[:top]
    summ["cprofile_total_s"] = float(st.total_tt)
    summ["cprofile_top_self_time"] = [
        {"function": (k[2] if k[0] == "~" else f"{Path(k[0]).name}:{k[1]}({k[2]})"), "self_s": float(tt),
         "cumulative_s": float(ct), "calls": int(nc)} for tt, ct, nc, k in rows]
    return out, summ
