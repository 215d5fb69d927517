"""The reducer interface: one base class, a declared option table, a registry.

A reducer is bound to one full-order model. Its constructor only validates and
stores options; ``reduce(r)`` returns a :class:`Reduction` (the reduced model and
a plain-data ``info`` record). Work that does not depend on r (Gramian factors,
converged shifts) may be kept on the reducer and reused by later calls.

Options are declared once per class in ``OPTIONS`` (name -> :class:`Option`);
defaults come from there, every value is validated against it with one message
format, unknown names are refused with the list of valid ones, and the full set
is copied into ``info["options"]``.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from numbers import Integral, Real
from typing import Any, Callable, ClassVar

import numpy as np

from ..errors import AccuracyWarning, ConvergenceWarning, InputError, OptionError
from ..linalg import accuracy
from ..linalg.warmup import warm_kernels
from ..utils import blas_threads, to_plain
from .outcome import CONVERGED_STATUSES, check_outcome, complete_outcome

__all__ = ["Option", "Reducer", "Reduction", "make", "available", "register", "get_class", "as_complex"]


#: BLAS threads used inside ``reduce`` (recorded in ``info["blas_threads"]``).
BLAS_THREADS = 1

@dataclass(frozen=True)
class Option:
    """One declared option: default, constraint and a one-line description.

    ``kind`` is one of "int", "float", "bool", "choice", "array", "any".
    ``low``/``high`` bound numbers (``open_low``/``open_high`` make them strict);
    ``choices`` lists the admissible values of a "choice"; ``nullable`` admits None.
    """

    default: Any
    kind: str
    doc: str = ""
    low: float | None = None
    high: float | None = None
    open_low: bool = False
    open_high: bool = False
    choices: tuple = ()
    nullable: bool = False

    def describe(self) -> str:
        """The admissible values in words, as error messages and option tables show them.

        For example ``"a float in (0, 1)"``, ``"an int in [1, inf)"`` or
        ``"one of 'auto', 'bt', 'residue'"``.
        """
        if self.kind == "choice":
            return "one of " + ", ".join(repr(c) for c in self.choices)
        if self.kind in ("int", "float"):
            lo = "-inf" if self.low is None else f"{self.low:g}"
            hi = "inf" if self.high is None else f"{self.high:g}"
            lb = "(" if self.open_low or self.low is None else "["
            rb = ")" if self.open_high or self.high is None else "]"
            return f"{'an int' if self.kind == 'int' else 'a float'} in {lb}{lo}, {hi}{rb}"
        return {"bool": "a bool", "array": "an array of numbers", "any": "a value"}[self.kind]

    def validate(self, owner: str, name: str, value):
        """Check ``value`` against this option's constraint and return it normalised.

        Parameters
        ----------
        owner : str
            The reducer's class name, for the message.
        name : str
            The option's name, for the message.
        value
            The value given.

        Returns
        -------
        value
            The value as the reducer uses it: ``bool``, ``int`` or ``float`` for those kinds
            (NumPy scalars converted), an ndarray for ``"array"``, the value itself
            otherwise; None if ``nullable``.

        Raises
        ------
        OptionError
            If the value is outside the constraint, in the form
            ``The 'tol' parameter of IRKA must be a float in (0, 1). Got -1 instead.``
            A bool is never accepted as a number; non-finite numbers and arrays with
            non-finite or non-numeric entries are refused.
        """
        def fail():
            raise OptionError(f"The {name!r} parameter of {owner} must be {self.describe()}"
                              f"{' or None' if self.nullable else ''}. Got {value!r} instead.")
        if value is None:
            if self.nullable:
                return None
            fail()
        if self.kind == "bool":
            if not isinstance(value, (bool, np.bool_)):
                fail()
            return bool(value)
        if self.kind == "choice":
            if value not in self.choices:
                fail()
            return value
        if self.kind in ("int", "float"):
            if isinstance(value, (bool, np.bool_)):
                fail()
            if self.kind == "int" and not isinstance(value, Integral):
                fail()
            if not isinstance(value, Real) or not math.isfinite(float(value)):
                fail()
            v = int(value) if self.kind == "int" else float(value)
            if self.low is not None and (v < self.low or (self.open_low and v == self.low)):
                fail()
            if self.high is not None and (v > self.high or (self.open_high and v == self.high)):
                fail()
            return v
        if self.kind == "array":
            try:
                arr = np.asarray(value)
            except Exception:
                fail()
            if arr.dtype == object or not np.issubdtype(arr.dtype, np.number) or not np.all(np.isfinite(arr)):
                fail()
            return arr
        return value


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

    Subclasses set ``name``, ``OPTIONS`` and implement ``_reduce(r) -> (rom, info)``.
    """

    name: ClassVar[str] = "base"
    OPTIONS: ClassVar[dict[str, Option]] = {}

    def __init__(self, fom, **options):
        from ..models.index3 import Index3Model

        if not isinstance(fom, Index3Model):
            raise InputError(f"fom must be an Index3Model; got {type(fom).__name__}")
        self.fom = fom
        unknown = sorted(set(options) - set(self.OPTIONS))
        if unknown:
            raise OptionError(f"{type(self).__name__} got unknown option(s) {', '.join(map(repr, unknown))}; "
                              f"valid options: {', '.join(sorted(self.OPTIONS))}")
        self.options = {}
        for key, opt in self.OPTIONS.items():
            self.options[key] = opt.validate(type(self).__name__, key, options.get(key, opt.default))
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

    def states_per_order(self) -> int:
        """First-order states per unit of ``r``: 2 for a second-order reduced model (r x r matrices,
        2r states; the default), 1 for a first-order one (r states). Cost: none."""
        return 2

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


# -- registry -------------------------------------------------------------
_REGISTRY: dict[str, Callable] = {}
_ENTRY_POINTS_LOADED = False


def register(name: str, cls):
    """Register a reducer class under ``name`` (third parties: entry-point group
    ``morsuite.reducers``)."""
    _REGISTRY[name] = cls
    return cls


def _load_entry_points():
    global _ENTRY_POINTS_LOADED
    if _ENTRY_POINTS_LOADED:
        return
    _ENTRY_POINTS_LOADED = True
    from importlib.metadata import entry_points

    for ep in entry_points(group="morsuite.reducers"):
        if ep.name not in _REGISTRY:
            try:
                _REGISTRY[ep.name] = ep.load()
            except Exception as exc:  # a broken plug-in must not break the suite
                warnings.warn(f"reducer entry point {ep.name!r} failed to load: {exc}")


def available() -> list[str]:
    """Names of the registered reducers."""
    _load_entry_points()
    return sorted(_REGISTRY)


def get_class(name: str):
    """The reducer class registered as ``name`` (also from ``morsuite.reducers`` entry points).

    Raises
    ------
    OptionError
        If no reducer has that name; the message lists the available ones.
    """
    _load_entry_points()
    if name not in _REGISTRY:
        raise OptionError(f"unknown reducer {name!r}; available: {', '.join(available())}")
    return _REGISTRY[name]


def make(name: str, fom, **options) -> Reducer:
    """Construct reducer ``name`` bound to ``fom`` with ``options``."""
    return get_class(name)(fom, **options)
