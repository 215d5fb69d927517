"""Input signals: grids, formulas against closed forms, CSV reading and resampling, specs."""

from __future__ import annotations

import numpy as np
import pytest

from morsuite.analysis import signals
from morsuite.errors import FileFormatError, InputError


def test_time_grid_keeps_the_step():
    t = signals.time_grid(1.0, 0.3)
    np.testing.assert_allclose(t, [0.0, 0.3, 0.6, 0.9, 1.2])
    assert signals.time_grid(1.0, 0.25).size == 5  # 1.0 / 0.25 is whole: no extra sample
    t, h = signals.check_time_grid(np.linspace(0.0, 7.0, 1_000_001))
    assert h == pytest.approx(7e-6)
    for bad in [(1.0, 0.0), (1.0, -1.0), (np.inf, 0.1), (1.0, np.nan), (1.0, 1.5)]:
        with pytest.raises(InputError):
            signals.time_grid(*bad)


def test_step_and_direction():
    t = signals.time_grid(4.0, 1.0)
    u = signals.step(t, m=2, amplitude=3.0, delay=2.0, direction=[1.0, -0.5])
    np.testing.assert_array_equal(u, [[0, 0], [0, 0], [3, -1.5], [3, -1.5], [3, -1.5]])
    np.testing.assert_array_equal(signals.step(t, m=3), np.ones((5, 3)))  # default: every input
    with pytest.raises(InputError, match="direction must have m = 2"):
        signals.step(t, m=2, direction=[1.0])
    with pytest.raises(InputError, match="m"):
        signals.step(t, m=0)


def test_impulse_marker():
    imp = signals.impulse(m=2, amplitude=2.0, direction=[1.0, 0.5])
    np.testing.assert_array_equal(imp.direction, [2.0, 1.0])
    assert imp.m == 2 and imp.samples(np.arange(3.0)).shape == (3, 2)


@pytest.mark.parametrize("method", ["linear", "log"])
def test_chirp_instantaneous_frequency(method):
    """d(phase)/dt, from the unwrapped analytic phase of the samples, follows the documented law."""
    w0, w1, T = 0.5, 5.0, 40.0
    t = signals.time_grid(T, 1e-3)
    u = signals.chirp(t, omega0=w0, omega1=w1, method=method)[:, 0]
    assert u[0] == 0.0 and np.max(np.abs(u)) <= 1.0
    law = w0 + (w1 - w0) * t / T if method == "linear" else w0 * (w1 / w0) ** (t / T)
    # phase from the closed form integral of the law, compared through sin
    phase = np.concatenate([[0.0], np.cumsum(0.5 * (law[1:] + law[:-1]) * np.diff(t))])
    np.testing.assert_allclose(u, np.sin(phase), atol=1e-5)
    with pytest.raises(InputError):
        signals.chirp(t, omega0=0.0, omega1=1.0, method="log")
    with pytest.raises(InputError, match="method"):
        signals.chirp(t, omega0=1.0, omega1=2.0, method="cubic")


def test_multisine():
    t = signals.time_grid(10.0, 0.01)
    u = signals.multisine(t, omegas=[1.0, 2.0], amplitudes=[1.0, 0.5], phases="zero")
    np.testing.assert_allclose(u[:, 0], np.sin(t) + 0.5 * np.sin(2 * t), atol=1e-14)  # the same formula: measured 0
    w = np.arange(1, 21) * 0.1
    t = signals.time_grid(200.0, 0.01)
    crest = {ph: np.max(np.abs(signals.multisine(t, omegas=w, phases=ph))) for ph in ("zero", "schroeder")}
    assert crest["schroeder"] < 0.5 * crest["zero"]  # the low crest factor it is chosen for
    with pytest.raises(InputError, match="phases"):
        signals.multisine(t, omegas=w, phases=[0.0])


def test_read_csv_header_separators_and_shift(tmp_path):
    p = tmp_path / "u.csv"
    p.write_text("time,force1,force2\n1.0,0,1\n1.5,1,1\n2.0,2,1\n")
    t, u = signals.read_csv(p, m=2)
    np.testing.assert_allclose(t, [0.0, 0.5, 1.0])
    np.testing.assert_allclose(u, [[0, 1], [1, 1], [2, 1]])
    q = tmp_path / "v.csv"
    q.write_text("0; 1\n0.5; 2\n")  # no header, semicolons
    t, u = signals.read_csv(q)
    assert u.shape == (2, 1)


def test_read_csv_resamples_nonuniform_times(tmp_path):
    p = tmp_path / "u.csv"
    tt = np.array([0.0, 0.1, 0.2, 0.4, 0.5, 0.6, 0.8, 0.9, 1.0])
    p.write_text("\n".join(f"{a},{2 * a + 1}" for a in tt))
    t, u = signals.read_csv(p)
    assert signals.check_time_grid(t)[1] == pytest.approx(0.1)  # the median spacing
    assert t[-1] == pytest.approx(1.0)
    # linear data survive linear interpolation (values <= 3 written exactly by repr: A)
    np.testing.assert_allclose(u[:, 0], 2 * t + 1, atol=1e-12)
    t, _ = signals.read_csv(p, step=0.25)
    np.testing.assert_allclose(t, [0.0, 0.25, 0.5, 0.75, 1.0])
    t, _ = signals.read_csv(p, step=0.3)  # the grid stops at the last multiple of the step
    np.testing.assert_allclose(t, [0.0, 0.3, 0.6, 0.9])
    with pytest.raises(InputError, match="equally spaced"):
        signals.read_csv(p, resample="error")


@pytest.mark.parametrize("text,err,match", [
    ("t,u\n0,1\n1,nan\n", InputError, "non-finite entry in row 2"),
    ("t,u\n0,1\n1,2,3\n", FileFormatError, "columns"),
    ("t,u\n", FileFormatError, "no data"),
    ("t,u\n0,1\n0,2\n", InputError, "strictly increasing"),
    ("0\n1\n", FileFormatError, "needs columns"),
    ("t,u\n0,1\n1,x\n", FileFormatError, "not numeric"),
])
def test_read_csv_bad_files(tmp_path, text, err, match):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(err, match=match):
        signals.read_csv(p)


def test_read_csv_channel_count(tmp_path):
    p = tmp_path / "u.csv"
    p.write_text("0,1,2\n1,1,2\n")
    with pytest.raises(InputError, match="2 input columns; the model has m = 3"):
        signals.read_csv(p, m=3)
    with pytest.raises(FileFormatError, match="does not exist"):
        signals.read_csv(tmp_path / "missing.csv")


def test_make_specs(tmp_path):
    t = signals.time_grid(2.0, 0.5)
    np.testing.assert_array_equal(signals.make("step", t, 2), np.ones((5, 2)))
    assert isinstance(signals.make("impulse", t, 1), signals.Impulse)
    u = signals.make("chirp:omega0=0.1,omega1=1,method=log", t, 1)
    np.testing.assert_allclose(u, signals.chirp(t, omega0=0.1, omega1=1.0, method="log"))
    u = signals.make({"kind": "multisine", "omegas": (1.0, 2.0)}, t, 1)
    np.testing.assert_allclose(u, signals.multisine(t, omegas=[1.0, 2.0]))
    p = tmp_path / "u.csv"
    p.write_text("t,u\n0,0\n4,4\n")
    np.testing.assert_allclose(signals.make(f"csv:{p}", t, 1)[:, 0], t)
    with pytest.raises(InputError, match="before the horizon"):
        signals.make(f"csv:{p}", signals.time_grid(5.0, 0.5), 1)
    with pytest.raises(InputError, match="unknown"):
        signals.make("square", t, 1)
    with pytest.raises(InputError, match="omega"):
        signals.make("chirp:omega=1", t, 1)


def test_make_direction_and_default_horizon_step(tmp_path):
    t = signals.time_grid(2.0, 0.5)
    np.testing.assert_array_equal(signals.make("step", t, 2, direction=[1.0, -2.0]),
                                  np.outer(np.ones(5), [1.0, -2.0]))
    b = signals.make("impulse", t, 2, direction=[0.0, 3.0]).direction
    np.testing.assert_array_equal(b, [0.0, 3.0])
    with pytest.raises(InputError, match="direction must have m = 2 entries"):
        signals.make("step", t, 2, direction=[1.0])
    with pytest.raises(InputError, match="given as well"):
        signals.make({"kind": "step", "direction": [1.0, 1.0]}, t, 2, direction=[1.0, 1.0])
    p = tmp_path / "u.csv"
    p.write_text("t,u\n0,0\n4,4\n")
    with pytest.raises(InputError, match="does not apply to a CSV input"):
        signals.make(f"csv:{p}", t, 1, direction=[1.0])
    # 2 pi / band_lo (one period of the band's lowest frequency), 0.3 / band_hi (21 steps a period at the top)
    horizon, step = signals.default_horizon_step((1e-3, 1.0))
    assert horizon == pytest.approx(2 * np.pi * 1e3) and step == pytest.approx(0.3)
    with pytest.raises(InputError, match="0 < lo < hi"):
        signals.default_horizon_step((1.0, 0.5))
