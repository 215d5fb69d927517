r"""Time-domain simulation of the constrained full model and of reduced models, and output errors.

``simulate(system, t, u)`` returns the output :math:`y(t_k)` of shape ``(len(t), p)``
from zero initial state for an :class:`~morsuite.models.Index3Model` (the scheme of
:mod:`morsuite.analysis.timestep`: trapezoidal rule on the saddle-point system, one
sparse LU, one solve per step, never :math:`\Pi`) or a reduced model
(:class:`~morsuite.rom.SecondOrderROM`, :class:`~morsuite.rom.FirstOrderROM`): the same
scheme on its dense first-order form (``rom_method="scheme"``) or python-control's
``forced_response`` (``rom_method="control"``: exact for an input that is linear
between samples, through the matrix exponential of an augmented matrix).

Why the same scheme is the default for reduced models: the scheme is linear, so
``y - y_r`` computed with it is the scheme applied to the error system
:math:`T - T_r`, whose discretisation error scales with the error itself. Mixing
an exact ROM solution with the full model's :math:`O(h^2)` solution adds the full
model's discretisation error to the reported reduction error (measured in
tests/test_simulate.py and docs/design/simulation.md).

:func:`output_errors` gives the max and :math:`L_2` norms of ``y - y_r`` over the
horizon, absolute and relative.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from ..errors import InputError, OptionError, StabilityWarning
from ..utils import to_plain
from .signals import Impulse, check_time_grid
from .timestep import SCHEMES, march_first_order, march_index3

__all__ = ["simulate", "output_errors", "OPTIONS"]

#: option -> (default, admissible values or type, description)
OPTIONS = {
    "scheme": ("trapezoidal", tuple(SCHEMES), "time-stepping rule (order 2, or 1 and dissipative)"),
    "rom_method": ("scheme", ("scheme", "control"), "reduced models: the same scheme (dense) or "
                   "python-control's forced_response; ignored for the full model"),
    "return_state": (False, bool, "also return the state trajectory in info (x, v; memory len(t) x n1)"),
    "details": (False, bool, "return (y, info) instead of y"),
    "solver_options": (None, dict, "full model: options of fom.new_solver"),
}


def _options(options: dict) -> dict:
    unknown = sorted(set(options) - set(OPTIONS))
    if unknown:
        raise OptionError(f"unknown option {', '.join(map(repr, unknown))} of simulate; "
                          f"valid: {', '.join(OPTIONS)}")
    out = {}
    for name, (default, allowed, _) in OPTIONS.items():
        v = options.get(name, default)
        ok = (v is None and default is None) or (
            isinstance(v, (bool, np.bool_)) if allowed is bool else
            isinstance(v, allowed) if isinstance(allowed, type) else v in allowed)
        if not ok:
            want = "a bool" if allowed is bool else f"a {allowed.__name__}" if isinstance(allowed, type) \
                else "one of " + ", ".join(map(repr, allowed))
            raise OptionError(f"The {name!r} parameter of simulate must be {want}. Got {v!r} instead.")
        out[name] = bool(v) if allowed is bool else v
    if out["return_state"] and not out["details"]:
        raise OptionError("return_state=True needs details=True: the trajectory is returned in info")
    return out


def _samples(u, t, m) -> np.ndarray:
    """The input samples (len(t), m) from an array or a callable u(t) -> (m,), validated."""
    nt = t.size
    if callable(u):
        try:
            rows = [np.asarray(u(tk), dtype=float).reshape(-1) for tk in t]
        except (TypeError, ValueError) as exc:
            raise InputError(f"u(t) must return {m} real numbers; calling it failed: {exc}") from exc
        bad = [r.size for r in rows if r.size != m]
        if bad:
            raise InputError(f"u(t) returned {bad[0]} values; the model has m = {m} inputs")
        U = np.array(rows).reshape(nt, m)
    else:
        try:
            U = np.asarray(u)
        except (TypeError, ValueError) as exc:
            raise InputError(f"u must be an array of shape (len(t), m) or a callable; got {type(u).__name__}") from exc
        if np.iscomplexobj(U) or not (np.issubdtype(U.dtype, np.number) or U.dtype == bool):
            raise InputError(f"u must be real numbers; got dtype {U.dtype}")
        U = U.astype(float)
        if U.ndim == 1 and m == 1:
            U = U.reshape(-1, 1)
        if U.ndim != 2 or U.shape[0] != nt:
            hint = " (transposed? the time index comes first)" if U.shape[::-1] == (nt, m) else ""
            raise InputError(f"u must have shape (len(t), m) = ({nt}, {m}); got {U.shape}{hint}")
        if U.shape[1] != m:
            raise InputError(f"u has {U.shape[1]} channels (columns); the model has m = {m} inputs")
    finite = np.isfinite(U)
    if not np.all(finite):
        k = int(np.flatnonzero(~np.all(finite, axis=1))[0])
        raise InputError(f"u has non-finite samples (NaN or inf), first at t[{k}] = {t[k]:g}")
    return U


def simulate(system, t, u, **options):
    r"""Output of a full or reduced model for the input ``u`` on the grid ``t``, from rest.

    Parameters
    ----------
    system : Index3Model, SecondOrderROM or FirstOrderROM
    t : array_like, (nt,)
        Equally spaced times from 0 (:func:`~morsuite.analysis.signals.check_time_grid`):
        at least one step, finite, strictly increasing, constant step ``h`` to a
        relative 1e-6. :func:`~morsuite.analysis.signals.time_grid` builds one.
    u : array_like (nt, m), callable or Impulse
        Input samples (a 1-D array when m = 1), a function ``u(t) -> (m,)`` sampled
        at ``t``, or :func:`~morsuite.analysis.signals.impulse` (simulated as its
        initial-velocity equivalent; see :class:`~morsuite.analysis.signals.Impulse`).
        Between samples the input is taken as linear.
    scheme : {"trapezoidal", "backward-euler"}
        Default ``"trapezoidal"``: the trapezoidal rule / Newmark average
        acceleration, order 2 in x, v and y, no numerical damping (energy of an
        undamped model conserved exactly). ``"backward-euler"``: order 1, damps
        the modes with :math:`\omega h \gtrsim 1`.
    rom_method : {"scheme", "control"}
        Reduced models only (default ``"scheme"``, see the module docstring).
    return_state : bool
        Default False. True puts ``x`` and ``v`` (nt, n1), the multiplier estimates
        ``z`` with their times ``z_t`` (full model: :math:`\mu_n/2 \approx
        z(t_{n+1/2})`), or ``w`` (nt, states) for a reduced model into ``info``
        (needs ``details=True``). Otherwise memory is O(n1 + nnz) beyond
        ``u`` and ``y``, whatever the number of steps.
    details : bool
        Default False. True returns ``(y, info)``.
    solver_options : dict, optional
        Full model: options of ``fom.new_solver`` (e.g. ``backward_tol``).

    Returns
    -------
    y : ndarray (nt, p)
    info : dict (with ``details=True``)
        ``system``, ``integrator``, ``step``, ``steps``, ``horizon``, ``input``,
        ``options``, ``lu_count``, ``solves``, ``time_s`` (and its parts),
        ``growth`` (bool), ``unstable_poles``, ``growth_factor``
        (:math:`e^{T \max \mathrm{Re}\,\lambda}` over unstable poles, reduced models),
        ``constraint_residual`` (full model, at the last step: :math:`\|G x\| / (\|G\| \|x\|)`
        and :math:`\|G v\| / (\|G\| (\|v\| + s \|x\|))`, max-norms, :math:`s = 2/h`).

    Raises
    ------
    InputError
        Bad ``t`` (not uniform, not from 0, non-finite, a step larger than the
        horizon) or ``u`` (wrong shape or channel count, non-finite samples).
    OptionError
        Unknown or invalid option.

    Warns
    -----
    StabilityWarning
        A reduced model with poles in the right half-plane (its output grows:
        ``info["growth"]``), or a non-finite output (overflow).

    Notes
    -----
    Cost. Full model: one sparse LU of :math:`S(2/h)` (:math:`S(1/h)` for backward
    Euler), one checked solve, then one solve and one sparse product with
    :math:`[-2K, 2sM, F]` (rows permuted and scaled) per step; an impulse adds
    one LU of :math:`[[M, G^T], [G, 0]]` and one solve. Reduced models: one dense
    LU of :math:`sE - A` and a matrix-vector product per step, or an
    :math:`(k + 2m)^2` matrix exponential (``"control"``).
    """
    from ..models import Index3Model
    from ..rom import FirstOrderROM, SecondOrderROM

    opts = _options(options)
    if not isinstance(system, (Index3Model, SecondOrderROM, FirstOrderROM)):
        raise InputError(f"system must be an Index3Model, SecondOrderROM or FirstOrderROM; "
                         f"got {type(system).__name__}")
    t, h = check_time_grid(t)
    m = system.m
    if isinstance(u, Impulse):
        if u.m != m:
            raise InputError(f"u is an impulse with {u.m} channels; the model has m = {m} inputs")
        U, b = np.zeros((t.size, m)), np.asarray(u.direction, dtype=float)
    else:
        U, b = _samples(u, t, m), None
    t0 = time.perf_counter()
    info = {"step": h, "steps": t.size - 1, "horizon": float(t[-1]),
            "input": "impulse" if b is not None else "samples", "options": dict(opts)}
    if isinstance(system, Index3Model):
        Y, run = march_index3(system, t, h, U, scheme=opts["scheme"], impulse=b,
                              return_state=opts["return_state"], solver_options=opts["solver_options"])
        info.update(system="full", integrator=opts["scheme"], unstable_poles=None, growth_factor=None)
        info["options"]["rom_method"] = None
    else:
        Y, run = _simulate_rom(system, t, h, U, b, opts)
        info.update(system=f"{system.kind} ROM")
    info.update(run)
    finite = bool(np.all(np.isfinite(Y)))
    info["finite"] = finite
    info["growth"] = bool(not finite or (info.get("unstable_poles") or 0) > 0)
    if not finite:
        warnings.warn(f"the simulated output of {info['system']} is not finite (overflow): the model "
                      "or the step is unstable; info['growth'] is True", StabilityWarning, stacklevel=2)
    info["time_s"] = time.perf_counter() - t0
    return (Y, info) if opts["details"] else Y


def _simulate_rom(rom, t, h, U, b, opts):
    fo = rom.to_first_order()
    E, A, B, C, D = fo.E, fo.A, fo.B, fo.C, fo.D
    w0 = None if b is None else np.linalg.solve(E, B @ b)
    lam = rom.poles()
    # poles computed on the imaginary axis come out with |Re| ~ eps |lambda|
    unstable = lam.real > np.sqrt(np.finfo(float).eps) * np.maximum(1.0, np.abs(lam))
    run = {"unstable_poles": int(np.count_nonzero(unstable)),
           "growth_factor": float(np.exp(min(t[-1] * lam.real[unstable].max(), 700.0))) if unstable.any() else 1.0}
    if unstable.any():
        warnings.warn(f"the reduced model has {run['unstable_poles']} poles in the right half-plane "
                      f"(max Re = {lam.real[unstable].max():.3g}; growth factor {run['growth_factor']:.3g} "
                      "over the horizon): its output grows and its error against the full model is "
                      "meaningless; info['growth'] is True", StabilityWarning, stacklevel=3)
    if opts["rom_method"] == "scheme":
        Y, r = march_first_order(E, A, B, C, D, t, h, U, scheme=opts["scheme"], w0=w0,
                                 return_state=opts["return_state"])
        run.update(r, integrator=opts["scheme"])
        return Y, run
    import control

    resp = control.forced_response(rom.to_control(), T=t, U=U.T, X0=0.0 if w0 is None else w0,
                                   return_states=True, squeeze=False)
    run.update(integrator="control.forced_response (input linear between samples)", lu_count=0, solves=0)
    if opts["return_state"]:
        run["w"] = np.asarray(resp.states).T
    return np.asarray(resp.outputs).reshape(C.shape[0], t.size).T, run


def output_errors(y, y_r, t) -> dict:
    r"""Max and :math:`L_2` norms of :math:`e = y - y_r` over the horizon, absolute and relative.

    The channels are combined by the Euclidean norm :math:`\|e(t)\|_2` (for p = 1 the
    absolute value):

    .. math::

        \|e\|_{\max} = \max_k \|e(t_k)\|_2, \qquad
        \|e\|_{L_2} = \Big(\int_0^T \|e(t)\|_2^2\,dt\Big)^{1/2}

    with the trapezoidal quadrature on the grid (second order, like the scheme).
    Relative versions divide by :math:`\max_k \|y(t_k)\|_2` and :math:`\|y\|_{L_2}`
    (``inf`` if only ``y`` vanishes, 0 if both do). With these norms
    :math:`\max_t \|e(t)\|_2 \le \|T - T_r\|_{H_2} \|u\|_{L_2}` holds for every L2
    input, SISO and MIMO (Cauchy-Schwarz on :math:`e = \int h_e(t - \tau) u(\tau) d\tau`).

    Returns
    -------
    dict
        ``max_output_error``, ``l2_output_error``, ``max_output_rel_error``,
        ``l2_output_rel_error``, ``max_output``, ``l2_output``, ``t_max_error``,
        ``max_output_error_per_channel`` (list), ``channel_norm``. A non-finite
        ``y_r`` gives infinite errors.
    """
    t, h = check_time_grid(t)
    ys = []
    for name, a in (("y", y), ("y_r", y_r)):
        a = np.asarray(a, dtype=float)
        a = a.reshape(-1, 1) if a.ndim == 1 else a
        if a.ndim != 2 or a.shape[0] != t.size:
            raise InputError(f"{name} must have shape (len(t), p) = ({t.size}, p); got {np.shape(a)}")
        ys.append(a)
    y, y_r = ys
    if y.shape != y_r.shape:
        raise InputError(f"y and y_r have different shapes {y.shape} and {y_r.shape}")
    if not np.all(np.isfinite(y)):
        raise InputError("y (the reference output) has non-finite entries")
    e = y - y_r
    with np.errstate(over="ignore", invalid="ignore"):
        en, yn = np.linalg.norm(e, axis=1), np.linalg.norm(y, axis=1)
        bad = not np.all(np.isfinite(en))

        def l2(v):
            return float(np.sqrt(h * (np.sum(v * v) - 0.5 * (v[0] ** 2 + v[-1] ** 2))))

        mx = np.inf if bad else float(en.max())
        le = np.inf if bad else l2(en)
    my, ly = float(yn.max()), l2(yn)

    def rel(a, b):
        return a / b if b > 0 else (np.inf if a > 0 else 0.0)

    per = np.where(np.all(np.isfinite(e), axis=0), np.abs(np.nan_to_num(e)).max(axis=0), np.inf)
    return to_plain({"max_output_error": mx, "l2_output_error": le, "max_output_rel_error": rel(mx, my),
                     "l2_output_rel_error": rel(le, ly), "max_output": my, "l2_output": ly,
                     "t_max_error": float(t[int(np.nanargmax(np.where(np.isfinite(en), en, np.inf)))]),
                     "max_output_error_per_channel": per, "channel_norm": "euclidean (2-norm over the p outputs)"})
