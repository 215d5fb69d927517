"""Benchmark ``romfiles``: what saving and verifying a reduced model costs, and what verify's band rule rests on.

Three measurements, quoted in ``docs/design/romfiles.md``:

- the model's content hash (:func:`morsuite.romfiles.model_hash`, canonical CSR) against the
  as-stored digest of :meth:`~morsuite.models.Index3Model.digest`, alternating, three times each,
  at fem_block(n1=20000) (quick: 2000); medians and their ratio measured in the same run;
- :func:`~morsuite.romfiles.save_rom` and :func:`~morsuite.romfiles.load_rom` of a dense
  second-order reduced model of order 200 (both formats, the sidecar, the hash check);
- the LU values' error level behind ``morsuite verify``'s band rule
  (:data:`morsuite.analysis.verify.LU_FACTOR`): on 200 log-spaced frequencies of the model's band,
  :math:`\\rho_b = \\max_\\omega \\sigma_{\\max}(T_b(j\\omega) - T(j\\omega)) / \\sigma_{\\max}(T(j\\omega))`
  for each LU backend b (its LU's value :math:`T_b` against the refined :math:`T`), on tcom(300) and
  fem_block(2000) (quick: tcom(100), fem_block(500)). Reported: each level, the largest ratio of two
  backends' levels (verify allows ``LU_FACTOR`` = 10 times its own) and, for contrast, the largest
  ratio of their errors at one frequency (where one is small by chance).
"""

from __future__ import annotations

import itertools
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from . import benchmark
from .backends import _load, _versions

__all__ = ["bench_romfiles", "hash_timing", "lu_error_levels"]

BACKENDS = ("superlu", "banded", "klu", "rslab")


def hash_timing(spec: str, repeats: int = 3) -> dict:
    """Median seconds of :func:`~morsuite.romfiles.model_hash` and of ``fom.digest()`` (each recomputed:
    the cached value dropped), alternating, and their ratio."""
    from .. import models
    from ..romfiles import model_hash

    fom = models.parse(spec)
    times = {"model_hash": [], "digest": []}
    for i in range(repeats):
        for k in (("model_hash", "digest") if i % 2 == 0 else ("digest", "model_hash")):
            fom.cache.pop(k, None)
            t0 = time.perf_counter()
            model_hash(fom) if k == "model_hash" else fom.digest()
            times[k].append(time.perf_counter() - t0)
    med = {k: float(np.median(v)) for k, v in times.items()}
    nnz = int(sum(getattr(fom, k).nnz for k in ("M", "D", "K", "G")))
    return {"model": spec, "n1": fom.n1, "n2": fom.n2, "nnz": nnz, "model_hash_s": med["model_hash"],
            "digest_s": med["digest"], "hash_over_digest": med["model_hash"] / med["digest"], "times": times}


def save_load_timing(order: int = 200) -> dict:
    """Seconds of :func:`~morsuite.romfiles.save_rom` (both formats and the sidecar) and of
    :func:`~morsuite.romfiles.load_rom` of each file, for a random dense second-order model."""
    from ..rom import SecondOrderROM
    from ..romfiles import load_rom, save_rom

    rng = np.random.default_rng(0)
    X = rng.standard_normal((order, order))
    rom = SecondOrderROM(np.eye(order), 0.1 * np.eye(order), X @ X.T + order * np.eye(order),
                         rng.standard_normal((order, 2)), rng.standard_normal((3, order)))
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        npz, mat, _ = save_rom(rom, Path(tmp) / "rom")
        t_save = time.perf_counter() - t0
        out = {"order": order, "save_s": t_save, "bytes": {"npz": npz.stat().st_size, "mat": mat.stat().st_size}}
        for path in (npz, mat):
            t0 = time.perf_counter()
            back = load_rom(path)
            out[f"load_{path.suffix[1:]}_s"] = time.perf_counter() - t0
            out[f"{path.suffix[1:]}_bit_identical"] = bool(back.K.tobytes() == rom.K.tobytes())
    return out


def lu_error_levels(spec: str, n: int = 200) -> dict:
    """Per backend, the relative error level of the LU's values of T(jw) on the band grid (refined values
    as the reference); the largest ratio of two levels and of two errors at one frequency."""
    from .. import models
    from ..analysis.response import band_response, sigma_max
    from ..norms._fom import FomResponse

    errs, skipped = {}, {}
    for backend in BACKENDS:
        fom = models.parse(spec)  # a fresh model: its memo of T(jw) is per model
        try:
            fom.lu_backend = backend
            omega = np.logspace(np.log10(fom.band[0]), np.log10(fom.band[1]), n)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                H0, _ = band_response(fom, omega, threads=1)
        except Exception as exc:  # a backend not installed: said, not fatal
            skipped[backend] = f"{type(exc).__name__}: {exc}"
            continue
        ev = FomResponse(fom, refine=1, memo=True)
        T = np.stack([np.asarray(ev.sample(1j * w)[1], dtype=complex) for w in omega])
        errs[backend] = (sigma_max(H0 - T), sigma_max(T))
    level = {b: float(np.max(d / s)) for b, (d, s) in errs.items()}
    pairs = list(itertools.permutations(errs, 2))
    level_ratio = max((level[b] / level[a] for a, b in pairs), default=float("nan"))
    pointwise = max((float(np.max(errs[b][0] / np.maximum(errs[a][0], 1e-300))) for a, b in pairs),
                    default=float("nan"))
    return {"model": spec, "levels": level, "level_ratio": level_ratio, "pointwise_ratio": pointwise,
            "skipped": skipped}


@benchmark("romfiles")
def bench_romfiles(quick: bool) -> dict:
    """Model hash against the stored digest, save/load of a reduced model, and LU error levels by backend."""
    from ..analysis.verify import LU_FACTOR
    from ..linalg.warmup import warm_kernels

    warm_kernels()
    load0 = _load()
    hashed = hash_timing("fem_block:n1=2000" if quick else "fem_block:n1=20000")
    print(f"{hashed['model']} ({hashed['nnz']} nonzeros): model_hash {hashed['model_hash_s']:.3f} s, "
          f"digest {hashed['digest_s']:.3f} s")
    files = save_load_timing()
    print(f"save_rom order {files['order']}: {files['save_s']:.3f} s; load .npz {files['load_npz_s']:.4f} s, "
          f".mat {files['load_mat_s']:.4f} s")
    levels = []
    for spec in (("tcom:nc=100", "fem_block:n1=500") if quick else ("tcom:nc=300", "fem_block:n1=2000")):
        row = lu_error_levels(spec)
        print(f"{spec}: LU error levels {', '.join(f'{b} {v:.2e}' for b, v in row['levels'].items())}; largest "
              f"ratio {row['level_ratio']:.2f} (at one frequency {row['pointwise_ratio']:.0f})")
        levels.append(row)
    ratios = {f"{row['model']}: largest ratio of two backends' LU error levels / LU_FACTOR": {
        "value": row["level_ratio"] / LU_FACTOR, "target": 1.0,
        "what": "verify allows another run's LU values an error level LU_FACTOR times its own"} for row in levels}
    ratios["model_hash / digest"] = {"value": hashed["hash_over_digest"], "target": None,
                                     "what": "canonical CSR hash against the as-stored digest, medians of 3"}
    return {"hash": hashed, "files": files, "lu_levels": levels, "lu_factor": LU_FACTOR, "ratios": ratios,
            "load_before": load0, "load_after": _load(), "versions": _versions(), "quick": quick}
