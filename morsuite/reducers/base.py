"""The reducer interface: one base class and a declared option table (the registry: :mod:`.registry`).

A reducer is bound to one full-order model. Its constructor only validates and
stores options; ``reduce(r)`` returns a :class:`Reduction` (the reduced model and
a plain-data ``info`` record). Work that does not depend on r (Gramian factors,
converged shifts) may be kept on the reducer and reused by later calls.

Options are declared once per class in ``OPTIONS`` (name -> :class:`Option`), the
advanced ones gathered in named ``GROUPS`` (:mod:`.options`); defaults come from there,
every value is validated against it with one message format, unknown names are refused
with the list of valid ones, and the full set is copied into ``info["options"]`` under
the options' own (flat) names.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from numbers import Integral
from typing import Any, ClassVar

import numpy as np

from ..errors import AccuracyWarning, ConvergenceWarning, InputError
from ..linalg import accuracy
from ..linalg.warmup import warm_kernels
from ..utils import blas_threads, to_plain
from .options import Group, Option, expand_options
from .outcome import CONVERGED_STATUSES, check_outcome, complete_outcome

__all__ = ["Option", "Group", "Reducer", "Reduction", "as_complex"]


#: BLAS threads used inside ``reduce`` (recorded in ``info["blas_threads"]``).
BLAS_THREADS = 1

@dataclass
class Reduction:
    """Result of ``reducer.reduce(r)``: the reduced model and a plain-data record."""

    rom: Any
    info: dict = field(default_factory=dict)

    @property
    def converged(self) -> bool:
        """``info["converged"]``: True only when the method's own optimality or fixed-point
        test passed on the full model (``status`` "converged", or "direct" for a method
        that does not iterate on its result; :mod:`morsuite.reducers.outcome`).

        A reduction that did not converge still returns its best iterate (with a
        :class:`~morsuite.errors.ConvergenceWarning`); ``status`` says how it ended.
        """
        return bool(self.info.get("converged", True))

    @property
    def status(self) -> str:
        """``info["status"]``: how the reduction ended, one of :data:`morsuite.reducers.outcome.STATUS`
        (for a record written without one, derived from ``converged`` as the base class does)."""
        return str(complete_outcome(dict(self.info))["status"])


class Reducer:
    """Base class: shared ``reduce`` (validation, timing, info), method hooks.

    Subclasses set ``name``, ``OPTIONS``, ``DESCRIPTION`` (a
    :class:`~morsuite.reducers.registry.Description`: a class that declares ``name`` and
    ``DESCRIPTION`` in its own body is registered by presence) and implement
    ``_reduce(r) -> (rom, info)``. Guide: ``docs/design/adding_a_reducer.md``.
    """

    name: ClassVar[str] = "base"
    OPTIONS: ClassVar[dict[str, Option]] = {}
    #: named groups of advanced options (:class:`~morsuite.reducers.options.Group`): every option not in a
    #: group is a top-level one
    GROUPS: ClassVar[dict[str, Group]] = {}
    #: a :func:`time.perf_counter` value after which an iterative reducer stops at the end of its current
    #: iteration with status ``"budget"`` and its best iterate (the IRKA family reads it); None: no deadline.
    #: Set by :class:`~morsuite.analysis.tolerance.ToleranceSearch` from its ``budget_s`` for each reduction,
    #: so that a time budget binds inside a long run, not only between runs.
    deadline: float | None = None

    def __init__(self, fom, **options):
        from ..models.index3 import Index3Model

        if not isinstance(fom, Index3Model):
            raise InputError(f"fom must be an Index3Model; got {type(fom).__name__}")
        self.fom = fom
        flat, given_as = expand_options(type(self).__name__, self.OPTIONS, self.GROUPS, options)
        self.options = {}
        for key, opt in self.OPTIONS.items():
            self.options[key] = opt.validate(type(self).__name__, given_as.get(key, key), flat.get(key, opt.default))
        self._deflate_rigid()
        self._check_options()
        self._warnings: list[str] = []

    def _deflate_rigid(self):
        """Free-floating models: bind the reducer to the flexible part (``morsuite.models.rigid``).

        ``self.model`` is the model given; ``self.fom`` the one the method reduces: the model
        itself, or for a model with rigid-body modes its flexible part (the rigid-body modes
        deflated by k constraint rows :math:`\\Phi^TMx = 0`). :meth:`reduce` adds the rigid part
        back exactly (:func:`~morsuite.models.rigid.with_rigid`). Refuses a model whose damping
        couples rigid and flexible modes (:class:`~morsuite.errors.ModelError`).
        """
        from ..models.rigid import flexible_part, rigid_body_modes

        self.model = self.fom
        self._rigid = rigid_body_modes(self.fom)
        if self._rigid.k:
            self.fom = flexible_part(self.fom)

    def _check_options(self):
        """Hook: cross-option checks."""

    # -- what the reducer says of itself and its route to a tolerance (analysis.tolerance) --------
    #: True for a method whose every order costs a run of its own (an iteration of LUs): a tolerance
    #: search steers it by a cheap proxy's error curve (analysis.tolerance.PROXY) instead of trying orders
    costly_orders: ClassVar[bool] = False

    @classmethod
    def states_for(cls, options: dict) -> int:
        """First-order states per unit of ``r`` with ``options`` (every declared option, validated): 2 for
        a second-order reduced model (r x r matrices, 2r states), 1 for a first-order one (r states), as
        ``DESCRIPTION.result`` says (default 2); a reducer whose result depends on an option
        (``result="by-option"``: bt's ``form``) overrides this. Cost: none."""
        desc = getattr(cls, "DESCRIPTION", None)
        return 1 if getattr(desc, "result", None) == "first-order" else 2

    def states_per_order(self) -> int:
        """First-order states per unit of ``r`` of this reducer: :meth:`states_for` of its options. Cost: none."""
        return self.states_for(self.options)

    def order_guess(self, tol: float, *, measure: str, scale: float) -> int | None:
        """Hook: a first guess of the order ``r`` whose error meets ``tol`` (relative; ``scale`` the
        absolute norm it is relative to, ``measure`` one of "band", "h2", "hinf"), from what this
        reducer has already computed (e.g. Hankel singular values), or None (default: no guess).
        A guess only steers :class:`~morsuite.analysis.tolerance.ToleranceSearch`; every order it
        returns is verified. Cost: at most the r-independent work the first reduction pays anyway."""
        return None

    def continue_from(self, rom) -> bool:
        """Hook: start the next :meth:`reduce` from ``rom``, an earlier result of this reducer at a
        smaller or larger order (continuation in r: its poles and residue directions as the next
        interpolation data); True when the reducer uses it (default False: nothing to continue).
        Cost: none here; the next reduction's."""
        return False

    def _continued_record(self):
        """Hook: what ``info["continued_from"]`` says of the last call's start (``{"order", "states"}`` of the
        model it continued from), None for a fresh start (the default)."""
        return None

    def get_params(self) -> dict:
        """Options as plain data (arrays as lists), as recorded in ``info``."""
        return {k: to_plain(v) for k, v in self.options.items()}

    def max_order(self) -> int:
        """Largest admissible r (the dimension of the hidden manifold by default)."""
        return self.fom.order

    def _validate_r(self, r) -> int:
        if isinstance(r, (bool, np.bool_)) or not isinstance(r, Integral):
            raise InputError(f"r must be a positive integer; got {r!r}")
        r = int(r)
        if r < 1:
            raise InputError(f"r must be a positive integer; got {r}")
        if r > self.max_order():
            raise InputError(f"r = {r} exceeds the order of the full model on its hidden manifold "
                             f"(n1 - n2 = {self.max_order()}) for {self.name}")
        return r

    #: whether the method's solves go through the model's saddle-point solvers (``info["lu_backend"]``)
    saddle_lu: ClassVar[bool] = True

    def warn(self, message: str, category=UserWarning, stacklevel: int = 3):
        """Issue a warning and record it in ``info['warnings']``."""
        self._warnings.append(f"{category.__name__}: {message}")
        warnings.warn(message, category, stacklevel=stacklevel)

    def reduce(self, r) -> Reduction:
        """Reduce to order ``r``; see the subclass for what r means (always also in info).

        Every ``info`` carries ``status`` and ``converged`` (consistent: checked), ``lu_count``,
        ``lu_count_shared`` (:mod:`morsuite.reducers.outcome`), ``time_s``, ``r``, ``states``,
        ``stable``, ``warnings``, ``options``, and what the checked saddle-point solves of the call
        reached (:mod:`morsuite.linalg.accuracy`): ``solve_backward_error`` (the worst certified
        backward error; None if none was checked) and ``solve_accuracy`` (``backward_error``,
        ``target``, ``met``, ``checked``, ``above_target``, ``refinement_steps``, ``fallback_lus``);
        a call with a solve above its target also gets an :class:`~morsuite.errors.AccuracyWarning`.

        On a model with k rigid-body modes (:mod:`morsuite.models.rigid`) the method reduces the
        flexible part to order r and the result is that model with the rigid part added back:
        order r + k (N + 2k states for a first-order model), ``info["r_flexible"]``,
        ``info["rigid_modes"]`` (their count and detection record: its LU is the model's,
        paid once and not in ``lu_count``), ``stable`` of the flexible part (the rigid poles at
        0 are kept by design), and ``rom.flexible`` the flexible part's reduced model. A model whose
        rigid-body detection failed or is incomplete is reduced as detected, with a warning,
        ``info["rigid_modes"]`` (the detection's ``status`` and ``reason``) and, where the method
        said ``converged`` or ``direct``, status ``detection-failed`` (the method's own in
        ``method_status``; :mod:`morsuite.reducers.outcome`).
        """
        r = self._validate_r(r)
        self._warnings = []
        # the dense work of a reducer is on tall-skinny n1 x r blocks and r x r
        # matrices, where BLAS threads only add synchronisation (10x slower on a
        # loaded 2-core machine, measured): pin BLAS to BLAS_THREADS for the run
        warm_kernels()  # numba's compile (or cache load) is not the reduction's time
        with blas_threads(BLAS_THREADS), accuracy.recording() as solves:
            t0 = time.perf_counter()
            rom, info = self._reduce(r)
            elapsed = time.perf_counter() - t0
        if rom.order == 0:  # every basis vector vanished: nothing of T reaches the inputs and outputs
            raise InputError(f"r = {r}: {self.name} found no direction to keep (reduced model of order 0): the "
                             f"transfer function of {self.model.name} vanishes on ker G (inputs F or outputs L act "
                             "only on constrained coordinates?)")
        rigid = {}
        if self._rigid.k:  # a free-floating model: the rigid part added back exactly, the flexible part's stability
            from ..models.rigid import with_rigid
            info.setdefault("stable", bool(rom.is_stable()))
            rom = with_rigid(self.model, rom)
            rigid = {"rigid_modes": self._rigid.summary(), "r_flexible": int(rom.flexible.order)}
        detection = self._rigid.info.get("status", "ok")
        if detection != "ok":  # the detection failed or is incomplete: said, recorded, never converged
            rigid.setdefault("rigid_modes", self._rigid.summary())
            self.warn(f"{self.name}: rigid-body detection on {self.model.name} {detection}: "
                      f"{self._rigid.info.get('reason')}", ConvergenceWarning)
        base = {"method": self.name, "model": self.model.name, "r_requested": r,
                "r": int(rom.order), "kind": rom.kind, "states": int(rom.states),
                "time_s": elapsed, **rigid}
        base.update(info)
        complete_outcome(base)  # status <-> converged, lu_count, lu_count_shared (reducers.outcome)
        if detection != "ok" and base["status"] in CONVERGED_STATUSES:
            base.update(method_status=base["status"], status="detection-failed", converged=False,
                        status_reason=f"rigid-body detection {detection}: {self._rigid.info.get('reason')}")
        check_outcome(base, self.name)
        base.setdefault("iterations", 0)
        if "stable" not in base:
            base["stable"] = bool(rom.is_stable())
        base["blas_threads"] = BLAS_THREADS
        base["solve_accuracy"] = solves.as_info()
        base["solve_backward_error"] = solves.worst
        if not solves.met:
            self.warn(solves.message(), AccuracyWarning)
        if self.saddle_lu and hasattr(self.fom, "lu_analysis"):  # the sparse LU backend of the model's solvers
            base["lu_backend"] = self.fom.lu_analysis()
        base["continued_from"] = self._continued_record()
        base["warnings"] = list(self._warnings)
        base["options"] = self.get_params()
        return Reduction(rom=rom, info=to_plain(base))

    def _reduce(self, r):  # pragma: no cover - abstract
        raise TypeError(f"{type(self).__name__} must define the hook _reduce(r) -> (rom, info)")


def as_complex(value) -> np.ndarray:
    """Inverse of the plain-data form of complex arrays in ``info`` ({"re", "im"} entries)."""
    def conv(x):
        if isinstance(x, dict):
            return complex(x["re"], x["im"])
        if isinstance(x, list):
            return [conv(v) for v in x]
        return complex(x)
    return np.asarray(conv(value), dtype=complex)
