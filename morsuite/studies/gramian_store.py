"""A model's LR-ADI Gramian factors shared by the worker processes of a run, through the artifact cache.

:func:`morsuite.linalg.gramians.gramian_factors` keeps the factors in the model's cache, i.e.
per process. The workers of :func:`morsuite.studies.batch.shared_compute` each build their own
model objects, so before this store each worker that met a model paid its factors: at
n1 = 20,577 (fem_block(20000)) 204 LUs and 26 minutes per worker (docs/design/backends.md,
2026-11-28). With a :class:`GramianStore` set (:func:`~morsuite.linalg.gramians.use_store`),
the factors computed in one worker are written to the cache and every later reader in any
worker loads them; the batch computes them first, as a unit of their own
(:func:`compute_factors`), and starts the units that read them (and the paper's IRKA, which
may) after it.

An entry is keyed by the model's matrices (:meth:`~morsuite.models.index3.Index3Model.digest`),
its LU backend (the requested one and, for ``"auto"``, the one chosen), the LR-ADI options and
the numerical code (:func:`~morsuite.studies.cache.cache_key`); factors made with explicit shift
arrays are not stored. A loaded entry carries the LU count and time of the run that made it,
with ``computed=False``: every reader reports it as shared work it relied on, as for factors found
in the model's cache (docs/design/reducers.md, "Status and cost accounting").

Cost: writing the factors once (about 4 n1 k doubles: 230 MB on tcom(2000)), reading them once per
worker that needs them, and one LU of the saddle matrix of M per read (the projector of the
observability factor, when its projection was still pending).
"""

from __future__ import annotations

import time

from ..linalg import gramians
from .cache import Cache, cache_key

__all__ = ["GramianStore", "compute_factors", "KIND"]

#: the cache's kind of these entries
KIND = "gramian_factors"


class GramianStore:
    """The store of :func:`morsuite.linalg.gramians.use_store` in an artifact cache (module docstring).

    Parameters
    ----------
    cache : Cache
        Where entries are read (if ``cache.read``) and written (if ``cache.write``).
    salt : str
        Part of every key (default ""): a run that must not read earlier runs' entries (``--no-cache``)
        gives a salt of its own, so that its workers share only what it computes.
    """

    def __init__(self, cache: Cache, salt: str = ""):
        self.cache, self.salt = cache, str(salt)

    def __repr__(self):
        return f"GramianStore({self.cache!r}, salt={self.salt!r})"

    def key(self, fom, options: dict):
        """The entry's key, or None for options that are not plain data (explicit shift arrays)."""
        if not all(isinstance(v, (str, int, float)) for v in options.values()):
            return None
        backend = fom.lu_backend
        chosen = fom.lu_analysis().get("backend", backend) if backend == "auto" else backend
        return cache_key(KIND, model=fom.digest(), backend=[backend, chosen], options=dict(sorted(options.items())),
                         salt=self.salt)

    def load(self, fom, options: dict):
        """The factors stored for this model and these options, or None (no work when absent)."""
        key = self.key(fom, options)
        hit = None if key is None else self.cache.get(KIND, key)
        return None if hit is None else gramians.factors_from_arrays(fom, *hit)

    def save(self, fom, options: dict, factors) -> None:
        """Store ``factors`` (nothing for explicit shift arrays or a cache that does not write)."""
        key = self.key(fom, options)
        if key is not None:
            self.cache.put(KIND, key, *gramians.factors_to_arrays(factors))


def compute_factors(source: str, run_by: str = "") -> dict:
    """Worker task: the Gramian factors of model ``source`` with the default options, into the process's store.

    The worker's initializer sets the store (:func:`morsuite.studies.batch.shared_compute`); without
    one the factors stay in this process's model cache. Returns a plain record: ``lu_count`` and
    ``time_s`` of the LR-ADI run (0 and ``cached`` True when the store held them), ``converged``,
    ``rank`` of each factor, ``wall_s``, ``scheduler``; ``skipped`` for a model with rigid-body modes
    (a pole at 0: no Gramians; the reducers and norms work on its flexible part); or ``error`` for a failure of
    :data:`~morsuite.studies.task_common.CAUGHT` (the readers then meet it themselves).
    """
    from ..models.rigid import rigid_body_modes
    from .task_common import CAUGHT, model_of

    t0 = time.perf_counter()
    try:
        fom = model_of(source)
        if rigid_body_modes(fom).k:  # a pole at 0: its LR-ADI cannot converge; the readers use the flexible part's
            return {"kind": KIND, "skipped": "rigid-body modes: the readers use the flexible part's factors",
                    "lu_count": 0, "time_s": 0.0, "wall_s": time.perf_counter() - t0, "scheduler": run_by}
        gf = gramians.gramian_factors(fom)
    except CAUGHT as exc:
        return {"kind": KIND, "error": f"{type(exc).__name__}: {exc}", "wall_s": time.perf_counter() - t0,
                "scheduler": run_by}
    return {"kind": KIND, "lu_count": int(gf.lu_count) if gf.computed else 0,
            "time_s": float(gf.time_s) if gf.computed else 0.0, "cached": not gf.computed,
            "converged": gf.converged, "rank": [gf.controllability.rank, gf.observability.rank],
            "wall_s": time.perf_counter() - t0, "scheduler": run_by}
