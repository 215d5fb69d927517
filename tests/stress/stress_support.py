"""Shared settings and strategies of the stress tests (imported by the test modules).

``MORSUITE_STRESS_EXAMPLES`` (default 12) sets the number of hypothesis
examples per property test. Draws are derandomized: a given count always runs
the same examples (CI is reproducible); a larger count explores further.
"""

from __future__ import annotations

import os

import numpy as np
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

DEFAULT_EXAMPLES = 12


def examples() -> int:
    raw = os.environ.get("MORSUITE_STRESS_EXAMPLES", str(DEFAULT_EXAMPLES))
    try:
        n = int(raw)
    except ValueError:
        n = 0
    if n < 1:
        raise ValueError(f"MORSUITE_STRESS_EXAMPLES must be a positive integer; got {raw!r}")
    return n


EXAMPLES = examples()

STRESS = settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
                  suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                         HealthCheck.filter_too_much],
                  print_blob=True)


@st.composite
def model_params(draw, n1_max: int = 120, spreads=(0.0, 3.0, 6.0, 12.0), units: bool = True,
                 zeta_range=(-6.0, 1.0)):
    """Keyword arguments of ``ms.models.random_constrained`` (small models: fast examples)."""
    n1 = draw(st.integers(12, n1_max))
    n2 = draw(st.one_of(st.integers(1, min(5, n1 // 2)), st.integers(0, n1 // 2)))
    kw = dict(n1=n1, n2=n2, m=draw(st.integers(1, 3)), p=draw(st.integers(1, 3)),
              seed=draw(st.integers(0, 2**31 - 1)),
              zeta=float(10 ** draw(st.floats(*zeta_range))),
              damping=draw(st.sampled_from(["rayleigh", "dashpots"])),
              mass=draw(st.sampled_from(["lumped", "consistent"])),
              mass_spread=draw(st.sampled_from(spreads)), stiffness_spread=draw(st.sampled_from(spreads)),
              constraints=draw(st.sampled_from(["ties", "fixes", "general", "mixed"])),
              io=draw(st.sampled_from(["points", "dense"])))
    if units and draw(st.integers(0, 4)) == 0:
        kw.update(mass_unit=1e-6, stiffness_unit=1e9)
    return kw


def band_grid(fom, n=60):
    return np.logspace(np.log10(fom.band[0]), np.log10(fom.band[1]), n)
