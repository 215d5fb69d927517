r"""Seeded random stress cases: model parameters, check family, order and shifts.

Case ``i`` of master seed ``s`` is drawn from ``numpy.random.default_rng([s, i])``
alone, so any case reruns by its index (``python -m morsuite.stress --case i``)
and the draw does not depend on which reducers are registered.

A case names a model of :func:`~morsuite.models.random_constrained` (n1 in
20..300, n2 in 1..6 for 60 % of the draws, 0 for 10 %, up to n1/2 otherwise;
damping ratio :math:`\zeta = 10^{U(-6, 1)}`; mass and stiffness spreads of 0, 3,
6 or 12 decades; physical units g and kN/mm for 20 %), one check family
(weights reduce 5, agreement 2, nullspace 1, g-invariance 1.5, bt-bound 1.5),
a method (for ``reduce``: irka, irka-projected or bt; in half of the reduce cases, decided
by the second stream ``default_rng([s, i, 34])`` so that every other draw of the case is
unchanged, one of the engineering baselines that the reducers' registry names (:func:`engineering`:
modal, krylov, bt-fl today), chosen by rendezvous hashing of the case and each name so that a
reducer added later takes only the cases it wins), an order r in 1..12, an IRKA iteration count
in 1..3 and a seed for the check's own draws. Drawing costs no factorization (the registry's
discovery on first use).
"""

from __future__ import annotations

from dataclasses import dataclass

import zlib

import numpy as np
import scipy.sparse as sp

__all__ = ["FAMILIES", "RUNNER_MAXIT", "BT_MAXITER", "CORE", "engineering", "runner_options", "Case", "draw_model_params", "regime", "draw_case",
           "given_shifts", "transformed_g"]

FAMILIES = ("reduce", "agreement", "nullspace", "g-invariance", "bt-bound")
#: iteration cap of IRKA in the runner's reduce family (docs/design/stress.md)
RUNNER_MAXIT = 40
#: LR-ADI iteration cap of "bt" in the runner; a capped run ends converged=False with a ConvergenceWarning
BT_MAXITER = 150
#: the methods of the check families (agreement and g-invariance compare irka with irka-projected,
#: bt-bound checks bt's bound): drawn in the other half of the reduce cases
CORE = ("irka", "irka-projected", "bt")


def engineering() -> tuple:
    """The baselines drawn in half of the reduce cases: the package's reducers whose description
    names options for the stress runner (``Description.stress``: today modal, krylov, bt-fl),
    other than :data:`CORE`; plugins are never drawn. Sorted by name."""
    from .. import reducers
    return tuple(n for n in reducers.available() if n not in CORE and reducers.describe(n).stress is not None
                 and reducers.get_class(n).__module__.startswith("morsuite.reducers."))


def runner_options(method: str) -> dict:
    """The options of ``method`` in the runner's reduce family, from its description
    (``Description.stress``: IRKA's cap :data:`RUNNER_MAXIT`, LR-ADI's cap :data:`BT_MAXITER`, bt-fl's
    largest quadrature rule of 256 nodes, so that a case stays within seconds; the defaults otherwise)."""
    from .. import reducers
    return dict(reducers.describe(method).stress or {}) if method in reducers.available() else {}


def _rendezvous(names, seed_key) -> str:
    """The name whose own draw ``default_rng([*seed_key, crc32(name)])`` is largest: adding a name moves only
    the cases it wins, and the choice does not depend on the names' order."""
    return max(names, key=lambda n: np.random.default_rng([*seed_key, zlib.crc32(n.encode())]).random())


def draw_model_params(rng: np.random.Generator, *, n1_range=(20, 300)) -> dict:
    """Keyword arguments of :func:`~morsuite.models.random_constrained` for one stress case."""
    n1 = int(rng.integers(n1_range[0], n1_range[1] + 1))
    u = rng.random()
    n2 = int(rng.integers(1, min(6, n1 // 2) + 1)) if u < 0.6 else (0 if u < 0.7 else int(rng.integers(1, n1 // 2 + 1)))
    spreads = [0.0, 0.0, 3.0, 6.0, 12.0]
    kw = dict(n1=n1, n2=n2, m=int(rng.integers(1, 4)), p=int(rng.integers(1, 4)), seed=int(rng.integers(0, 2**31 - 1)),
              zeta=float(10 ** rng.uniform(-6, 1)), damping=str(rng.choice(["rayleigh", "dashpots"])),
              mass=str(rng.choice(["lumped", "consistent"])),
              mass_spread=float(rng.choice(spreads)), stiffness_spread=float(rng.choice(spreads)),
              constraints=str(rng.choice(["ties", "fixes", "general", "mixed"])),
              io=str(rng.choice(["points", "dense"])))
    if rng.random() < 0.2:
        kw.update(mass_unit=1e-6, stiffness_unit=1e9)
    return kw


def regime(kw: dict) -> str:
    """A short label of a model's regime (damping and conditioning) for the summary."""
    z = kw.get("zeta", 0.05)
    damp = "undamped" if kw.get("damping") == "none" else ("light" if z < 1e-3 else "moderate" if z < 1 else "overdamped")
    spread = max(kw.get("mass_spread", 0.0), kw.get("stiffness_spread", 0.0))
    cond = "well" if spread == 0 else ("spread<=6" if spread <= 6 else "spread12")
    units = "+units" if kw.get("mass_unit", 1.0) != 1.0 or kw.get("stiffness_unit", 1.0) != 1.0 else ""
    return f"{damp}/{cond}{units}"


@dataclass
class Case:
    """One stress case (plain data): the check ``family`` of ``method`` at order ``r`` on ``model``."""

    index: int
    seed: int
    family: str
    method: str
    r: int
    maxit: int
    model: dict


def draw_case(index: int, master_seed: int = 0, families=None) -> Case:
    r"""Case ``index`` of the seeded sequence (independent of the other cases).

    The draw depends on morsuite's own reducers only (never on plugins), so a case
    index names the same case on every installation of one version; a reducer added
    to the package moves only the engineering cases it wins; a case that needs a
    missing reducer is run as ``skipped``. A ``bt-bound`` case is restricted
    to models on which LR-ADI converges within :data:`BT_MAXITER` (n1 <= 150,
    :math:`\zeta \in [10^{-1.5}, 1]`, spreads <= 3 decades).
    """
    rng = np.random.default_rng([master_seed, index])
    fams = list(families or FAMILIES)
    weights = {"reduce": 5.0, "agreement": 2.0, "nullspace": 1.0, "g-invariance": 1.5, "bt-bound": 1.5}
    w = np.array([weights[f] for f in fams])
    family = str(rng.choice(fams, p=w / w.sum()))
    kw = draw_model_params(rng)
    method = str(rng.choice(list(CORE))) if family == "reduce" else \
        ("bt" if family == "bt-bound" else "irka")
    r = int(rng.integers(1, 13))
    maxit = int(rng.integers(1, 4))
    seed = int(rng.integers(0, 2**31 - 1))
    if family == "reduce":
        extra = np.random.default_rng([master_seed, index, 34])
        if extra.random() < 0.5:
            method = _rendezvous(engineering(), (master_seed, index, 34))
    if family == "bt-bound":
        # the bound is a statement about converged Gramians; the reduce family runs bt on everything else
        kw.update(n1=min(kw["n1"], 150), n2=min(kw["n2"], min(kw["n1"], 150) // 2),
                  zeta=float(10 ** rng.uniform(-1.5, 0.0)), mass_spread=min(kw["mass_spread"], 3.0),
                  stiffness_spread=min(kw["stiffness_spread"], 3.0))
    return Case(index, seed, family, method, r, maxit, kw)


def given_shifts(fom, k, rng=None):
    """k initial shifts in the open right half-plane over the band (real, or with one conjugate pair)."""
    lo, hi = fom.band
    s = np.logspace(np.log10(lo), np.log10(hi), k).astype(complex)
    if rng is not None and k >= 3 and rng.random() < 0.5:
        w = s[k // 2].real
        s[k // 2 - 1], s[k // 2] = complex(0.3 * w, w), complex(0.3 * w, -w)
    return s


def transformed_g(fom, rng, *, max_decades=3.0):
    """The same model with the rows of G permuted and scaled by 10**U(-d, d), d = ``max_decades``.

    The hidden manifold ker G, hence the transfer function, is unchanged.
    """
    from ..models import Index3Model

    perm = rng.permutation(fom.n2)
    scale = 10 ** rng.uniform(-max_decades, max_decades, fom.n2)
    G2 = sp.diags(scale) @ fom.G[perm]
    return Index3Model(fom.M, fom.D, fom.K, G2, fom.F, fom.L, name=fom.name + "-Gt", band=fom.band)
