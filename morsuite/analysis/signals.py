r"""Input signals for time-domain simulation: time grids, step, impulse, chirp, multi-sine, CSV.

Every generator returns the samples ``u`` of shape ``(len(t), m)`` on a time grid
``t`` that starts at 0 with a constant step (see :func:`check_time_grid`), except
:func:`impulse`, which returns an :class:`Impulse` marker that
:func:`morsuite.analysis.simulate` turns into an initial velocity.

Multi-input models (``m > 1``): a scalar signal :math:`s(t)` drives every input
along one direction :math:`b \in \mathbb{R}^m`, :math:`u(t) = b\,s(t)`. The
default direction is ``b = ones(m)``: each input channel carries the whole signal
(a unit step is a unit step on every input), so :math:`\|u\|_{L_2} = \sqrt{m}
\|s\|_{L_2}`. Pass ``direction=`` for another one.

Between samples the simulators treat the input as piecewise linear: the
trapezoidal rule uses :math:`(u_n + u_{n+1})/2` on each step and
python-control's ``forced_response`` integrates the linear interpolant exactly.
A step at ``t = 0`` is therefore ``u(0) = 1``, constant on the whole horizon; a
delayed step whose delay falls between samples is smeared over one step.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import FileFormatError, InputError
from ..utils import band_pair

__all__ = ["STEP_RTOL", "check_time_grid", "time_grid", "default_horizon_step", "step", "impulse", "Impulse",
           "chirp", "multisine", "read_csv", "make"]

#: Relative tolerance of "constant step": every ``t[k+1] - t[k]`` within STEP_RTOL * h of h.
#: np.arange(n) * h and np.linspace(0, T, n + 1) differ from a constant step by a few ulps of
#: t[-1], i.e. n * 1e-16 relative to h: 1e-6 leaves room for 1e9 steps.
STEP_RTOL = 1e-6


def check_time_grid(t, name: str = "t"):
    """Validate an equally spaced time grid from 0; return ``(t, h)`` (float array, step).

    Raises :class:`InputError` (naming ``name``) unless ``t`` is 1-D with at least two
    samples, finite, starts at 0 (to ``STEP_RTOL * h``), is strictly increasing and
    has a constant step ``h = t[-1] / (len(t) - 1)`` to the relative tolerance
    :data:`STEP_RTOL`.
    """
    try:
        t = np.asarray(t, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be a 1-D array of times; got {type(t).__name__} ({exc})") from exc
    if t.ndim != 1:
        raise InputError(f"{name} must be 1-D; got shape {t.shape}")
    if t.size < 2:
        raise InputError(f"{name} must have at least two samples (one step); got {t.size}: "
                         "is the step larger than the horizon?")
    if not np.all(np.isfinite(t)):
        raise InputError(f"{name} has non-finite entries (NaN or inf) at index "
                         f"{int(np.flatnonzero(~np.isfinite(t))[0])}")
    dt = np.diff(t)
    if not np.all(dt > 0):
        k = int(np.flatnonzero(dt <= 0)[0])
        raise InputError(f"{name} must be strictly increasing; t[{k + 1}] = {t[k + 1]!r} <= t[{k}] = {t[k]!r}")
    h = (t[-1] - t[0]) / (t.size - 1)
    if abs(t[0]) > STEP_RTOL * h:
        raise InputError(f"{name} must start at 0 (zero initial state at t = 0); got t[0] = {t[0]!r}")
    dev = np.abs(dt - h)
    k = int(np.argmax(dev))
    if dev[k] > STEP_RTOL * h:
        raise InputError(f"{name} must be equally spaced (relative tolerance {STEP_RTOL:g}): step "
                         f"t[{k + 1}] - t[{k}] = {dt[k]!r} differs from the mean step {h!r}")
    return t, float(h)


def time_grid(horizon, step) -> np.ndarray:
    """The grid ``t = k * step``, k = 0..n, with ``n = ceil(horizon / step)`` (to 1e-9).

    The step is kept as given (it decides the accuracy); the last sample is at or
    just beyond ``horizon``. A step larger than the horizon raises :class:`InputError`.
    """
    horizon, step = _positive("horizon", horizon), _positive("step", step)
    if step > horizon:
        raise InputError(f"step {step!r} is larger than the horizon {horizon!r}: no step would be taken")
    n = int(np.ceil(horizon / step - 1e-9))
    return np.arange(n + 1) * step


def default_horizon_step(band) -> tuple[float, float]:
    r"""The default ``(horizon, step)`` for a model whose band is :math:`[\omega_{lo}, \omega_{hi}]` (rad/s).

    ``step`` :math:`= 0.3/\omega_{hi}`: about 21 steps per period of the band's highest
    frequency, where the trapezoidal rule's phase error is :math:`(\omega h)^3/12
    \approx 2.3\cdot 10^{-3}` rad per step (1.5% of a period over a period); lower
    frequencies, which dominate a step response, are resolved much better (halving
    the step moved the step response of tcom(2000) by 8e-8 and of dsms(2000) by
    2e-4 of its peak). ``horizon`` :math:`= 2\pi/\omega_{lo}`: one period of the
    band's lowest frequency, so the slowest dynamics the band covers show once
    (dsms: 628 s, 2095 steps, settled to 1e-8; tcom(2000): 6283 s, 20944 steps,
    2.4 s, still creeping by 3% over the last tenth: its slowest modes, near and
    below the band's lower end, are overdamped by the mass-proportional damping).
    """
    lo, hi = band_pair(band)
    return 2.0 * np.pi / lo, 0.3 / hi


def _positive(name, value):
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be a positive number; got {value!r}") from exc
    if not (np.isfinite(v) and v > 0):
        raise InputError(f"{name} must be a positive finite number; got {value!r}")
    return v


def _direction(m, direction):
    if isinstance(m, (bool, np.bool_)) or not isinstance(m, (int, np.integer)) or m < 1:
        raise InputError(f"m (number of inputs) must be a positive integer; got {m!r}")
    if direction is None:
        return np.ones(int(m))
    b = np.asarray(direction, dtype=float).reshape(-1)
    if b.size != m:
        raise InputError(f"direction must have m = {m} entries (one per input); got {b.size}")
    if not np.all(np.isfinite(b)):
        raise InputError("direction has non-finite entries")
    return b


def _along(t, s, m, direction, amplitude):
    amplitude = float(amplitude)
    if not np.isfinite(amplitude):
        raise InputError(f"amplitude must be finite; got {amplitude!r}")
    return np.outer(amplitude * s, _direction(m, direction))


def step(t, *, m: int = 1, amplitude: float = 1.0, delay: float = 0.0, direction=None) -> np.ndarray:
    r"""Step :math:`u(t) = a\,b\,[t \ge \text{delay}]`, shape ``(len(t), m)``."""
    t, _ = check_time_grid(t)
    return _along(t, (t >= float(delay)).astype(float), m, direction, amplitude)


@dataclass(frozen=True)
class Impulse:
    r"""A Dirac impulse :math:`u(t) = b\,\delta(t)` (``direction`` = b, amplitude included).

    Simulated as its initial-velocity equivalent: integrating
    :math:`M\ddot x + \dots + G^T z = F b\,\delta(t)` over :math:`[0^-, 0^+]` gives
    :math:`x(0^+) = 0` and the jump :math:`M v(0^+) + G^T \int z = F b` with the hidden
    constraint :math:`G v(0^+) = 0`, i.e.

    .. math::

        \begin{bmatrix} M & G^T \\ G & 0 \end{bmatrix}
        \begin{bmatrix} v(0^+) \\ \nu \end{bmatrix} = \begin{bmatrix} F b \\ 0 \end{bmatrix}

    (one sparse LU of the mass-constraint matrix), then zero input. A second-order
    reduced model starts from :math:`v(0^+) = \hat M^{-1} \hat F b`, a first-order one
    from :math:`w(0^+) = E^{-1} B b`; the term :math:`D b\,\delta(t)` that a
    feedthrough D adds to y cannot be sampled and is left out.
    """

    direction: np.ndarray

    @property
    def m(self) -> int:
        """Number of inputs, the length of :attr:`direction`."""
        return int(self.direction.size)

    def samples(self, t) -> np.ndarray:
        """The input after ``t = 0^+``: zeros of shape ``(len(t), m)``."""
        return np.zeros((np.size(t), self.m))


def impulse(*, m: int = 1, amplitude: float = 1.0, direction=None) -> Impulse:
    """Unit (times ``amplitude``) impulse at ``t = 0`` along ``direction`` (default ones(m))."""
    amplitude = float(amplitude)
    if not np.isfinite(amplitude):
        raise InputError(f"amplitude must be finite; got {amplitude!r}")
    b = amplitude * _direction(m, direction)
    b.flags.writeable = False
    return Impulse(b)


def chirp(t, *, omega0: float, omega1: float, t1: float | None = None, method: str = "linear",
          amplitude: float = 1.0, m: int = 1, direction=None) -> np.ndarray:
    r"""Frequency sweep :math:`u(t) = a\,b \sin\varphi(t)` from ``omega0`` to ``omega1`` (rad/s).

    ``method="linear"``: instantaneous frequency
    :math:`\omega(t) = \omega_0 + (\omega_1 - \omega_0)\,t/t_1`,
    :math:`\varphi(t) = \omega_0 t + (\omega_1 - \omega_0)\,t^2/(2 t_1)`.
    ``method="log"``: :math:`\omega(t) = \omega_0 k^{t/t_1}`, :math:`k = \omega_1/\omega_0`,
    :math:`\varphi(t) = \omega_0 t_1 (k^{t/t_1} - 1)/\ln k` (both frequencies > 0).
    ``t1`` (default: the last time of ``t``) is when ``omega1`` is reached; the sweep
    continues by the same law beyond it. The sweep starts at :math:`u(0) = 0`.
    Resolve the highest frequency with about 20 steps per period (``h <= 0.3 / omega1``)
    for 1%-accurate amplitudes with the trapezoidal rule (its phase error per step is
    :math:`(\omega h)^3/12`).
    """
    t, _ = check_time_grid(t)
    w0, w1 = float(omega0), float(omega1)
    t1 = float(t[-1]) if t1 is None else _positive("t1", t1)
    if not (np.isfinite(w0) and np.isfinite(w1)) or w0 < 0 or w1 < 0:
        raise InputError(f"omega0 and omega1 must be finite and >= 0; got {omega0!r}, {omega1!r}")
    if method == "linear":
        phi = w0 * t + (w1 - w0) * t * t / (2.0 * t1)
    elif method == "log":
        if w0 <= 0 or w1 <= 0:
            raise InputError(f"a log sweep needs omega0 > 0 and omega1 > 0; got {w0!r}, {w1!r}")
        if w0 == w1:
            phi = w0 * t
        else:
            lk = np.log(w1 / w0)
            phi = w0 * t1 * np.expm1(lk * t / t1) / lk
    else:
        raise InputError(f"method must be 'linear' or 'log'; got {method!r}")
    return _along(t, np.sin(phi), m, direction, amplitude)


def multisine(t, *, omegas, amplitudes=None, phases="schroeder", m: int = 1, direction=None) -> np.ndarray:
    r"""Sum of sines :math:`u(t) = b \sum_k a_k \sin(\omega_k t + \varphi_k)` (rad/s).

    ``amplitudes`` default to 1 each. ``phases``: ``"schroeder"`` (default,
    :math:`\varphi_k = -\pi k (k - 1)/K`, k = 1..K: a low crest factor, so the
    peak input stays near :math:`\sqrt{K/2}` rather than K), ``"zero"``, or an
    array of K phases (rad).
    """
    t, _ = check_time_grid(t)
    w = np.atleast_1d(np.asarray(omegas, dtype=float))
    if w.ndim != 1 or w.size == 0 or not np.all(np.isfinite(w)):
        raise InputError(f"omegas must be a non-empty 1-D array of finite frequencies; got {omegas!r}")
    a = np.ones(w.size) if amplitudes is None else np.broadcast_to(np.asarray(amplitudes, dtype=float), w.shape)
    if not np.all(np.isfinite(a)):
        raise InputError("amplitudes must be finite")
    if isinstance(phases, str):
        k = np.arange(1, w.size + 1)
        if phases == "schroeder":
            ph = -np.pi * k * (k - 1) / w.size
        elif phases == "zero":
            ph = np.zeros(w.size)
        else:
            raise InputError(f"phases must be 'schroeder', 'zero' or an array; got {phases!r}")
    else:
        ph = np.asarray(phases, dtype=float).reshape(-1)
        if ph.size != w.size or not np.all(np.isfinite(ph)):
            raise InputError(f"phases must be {w.size} finite numbers (one per frequency)")
    s = np.sin(np.outer(t, w) + ph) @ a
    return _along(t, s, m, direction, 1.0)


def read_csv(path, *, m: int | None = None, resample: str = "linear", step: float | None = None):
    r"""Measured input samples from a CSV file of columns ``t, u1, ..., um``; returns ``(t, u)``.

    A first line that does not parse as numbers is a header and is skipped; ``,``
    ``;`` or whitespace separate the columns. Every entry must be finite, the times
    strictly increasing, and (when ``m`` is given) the file must have ``m`` input
    columns. The times are shifted so that the first sample is at ``t = 0``.

    Resampling (``resample="linear"``, default): if the times are not equally spaced
    (to :data:`STEP_RTOL`), the samples are linearly interpolated onto the grid
    ``k * h``, k = 0, 1, ... up to the last time of the file, ``h = step`` or, by
    default, the median spacing of the file; linear interpolation is the rule the simulators apply
    between samples anyway. ``resample="error"`` refuses non-uniform times.
    """
    if resample not in ("linear", "error"):
        raise InputError(f"resample must be 'linear' or 'error'; got {resample!r}")
    p = Path(path)
    if not p.is_file():
        raise FileFormatError(f"input CSV {str(p)!r} does not exist")
    lines = [ln for ln in p.read_text().splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    rows = [ln.replace(";", ",").replace(",", " ").split() for ln in lines]
    if rows and not _numeric(rows[0]):
        rows = rows[1:]  # header
    if not rows:
        raise FileFormatError(f"input CSV {str(p)!r} has no data rows")
    width = len(rows[0])
    for i, r in enumerate(rows):
        if len(r) != width:
            raise FileFormatError(f"input CSV {str(p)!r}: row {i + 1} has {len(r)} columns; the first has {width}")
        if not _numeric(r):
            raise FileFormatError(f"input CSV {str(p)!r}: row {i + 1} is not numeric: {' '.join(r)!r}")
    data = np.array(rows, dtype=float)
    if width < 2:
        raise FileFormatError(f"input CSV {str(p)!r} needs columns t, u1, ..., um; got {width} column")
    if m is not None and width - 1 != m:
        raise InputError(f"input CSV {str(p)!r} has {width - 1} input columns; the model has m = {m} inputs")
    if not np.all(np.isfinite(data)):
        i, j = np.argwhere(~np.isfinite(data))[0]
        raise InputError(f"input CSV {str(p)!r} has a non-finite entry in row {i + 1}, column {j + 1}")
    t, u = data[:, 0] - data[0, 0], data[:, 1:]
    if t.size < 2 or not np.all(np.diff(t) > 0):
        raise InputError(f"input CSV {str(p)!r}: the times must be strictly increasing (two samples at least)")
    try:
        check_time_grid(t, name=f"the times of {p.name}")
        return t, u
    except InputError:
        if resample == "error":
            raise
    h = float(np.median(np.diff(t))) if step is None else _positive("step", step)
    grid = time_grid(t[-1], h)
    grid = grid[grid <= t[-1] * (1 + 1e-12)]
    return grid, np.column_stack([np.interp(grid, t, u[:, j]) for j in range(u.shape[1])])


def _numeric(tokens) -> bool:
    try:
        [float(x) for x in tokens]
    except ValueError:
        return False
    return bool(tokens)


def make(spec, t, m: int, *, direction=None):
    """An input from a spec: ``"step"``, ``"impulse"``, ``"chirp:omega0=0.01,omega1=1"``,
    ``"multisine:omegas=0.1;0.5"``, ``"csv:PATH"`` (or a dict ``{"kind": ..., **params}``).

    Returns the samples ``(len(t), m)`` or an :class:`Impulse`. A CSV is
    interpolated linearly onto ``t``, which must not extend beyond its last time.
    ``direction`` (m numbers) is the input direction of the generated signals
    (default ones(m)); a CSV has its own channels and takes none.
    Meant for the command line and the study scenes.
    """
    from ..models.catalog import _value

    if isinstance(spec, dict):
        params = dict(spec)
        kind = params.pop("kind", None)
    elif isinstance(spec, str) and spec:
        kind, _, rest = spec.partition(":")
        params = {}
        if kind == "csv":
            params["path"] = rest
        else:
            for item in filter(None, rest.split(",")):
                key, eq, val = item.partition("=")
                if not eq or not key:
                    raise InputError(f"input spec {spec!r}: expected key=value, got {item!r}")
                params[key.strip()] = _value(val.strip())
    else:
        raise InputError(f"input spec must be a non-empty string or a dict; got {spec!r}")
    if direction is not None:
        if kind == "csv":
            raise InputError("direction does not apply to a CSV input: its columns are the m input channels")
        if "direction" in params:
            raise InputError(f"input spec {spec!r} has a direction and direction= was given as well")
        params["direction"] = direction
    gens = {"step": step, "chirp": chirp, "multisine": multisine}
    try:
        if kind == "impulse":
            return impulse(m=m, **params)
        if kind in gens:
            return gens[kind](t, m=m, **params)
    except TypeError as exc:  # an unknown parameter name
        raise InputError(f"input spec {spec!r}: {exc}") from exc
    if kind == "csv":
        t, _ = check_time_grid(t)
        tc, uc = read_csv(params.pop("path"), m=m, **params)
        if t[-1] > tc[-1] * (1 + 1e-12):
            raise InputError(f"input CSV ends at t = {tc[-1]:g}, before the horizon {t[-1]:g}")
        return np.column_stack([np.interp(t, tc, uc[:, j]) for j in range(m)])
    raise InputError(f"input kind {kind!r} is unknown; available: step, impulse, chirp, multisine, csv")
