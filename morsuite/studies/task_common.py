"""What every task of a study's graph shares: the model it builds, its stamp, the ROM payload.

The tasks (:mod:`morsuite.studies.tasks`, :mod:`morsuite.studies.norms`, :mod:`morsuite.studies.timedomain`) are pure functions of plain
data; this module holds the few pieces they have in common, so that none of them
imports another:

- :data:`CAUGHT`: the failures of one r that are recorded instead of aborting a study;
- :func:`model_of`: the full model of a catalog string or file path, built once per
  process (a few are kept: the Gramian factors that norms and ``bt`` share live on it);
- :func:`stamp`: host, process and time of a result;
- :func:`rom_payload` / :func:`rom_from_payload`: a reduced model as plain data and back.
"""

from __future__ import annotations

import datetime
import functools
import os
import platform

import numpy as np

from ..errors import MorsuiteError

__all__ = ["CAUGHT", "model_of", "stamp", "rom_payload", "rom_from_payload"]

#: Failures of one r that are recorded (and reported) instead of aborting the study.
#: Anything else is a bug and propagates.
CAUGHT = (MorsuiteError, ArithmeticError, ValueError, RuntimeError, MemoryError, np.linalg.LinAlgError)


def model_of(source: str):
    """The full model of ``source`` (catalog string or file path), via
    :func:`morsuite.models.catalog.parse`, built once per process: a study's validation, its tasks and
    ``morsuite compare`` share it (and what is kept on it: the rigid-body detection, the Gramian
    factors, the memo of T(jw)). The last 4 are kept (``model_of.cache_clear()`` forgets them); a file
    is known by its path, size and modification time, so a file written anew is read anew."""
    return _model_of(source, _file_stamp(source))


def _file_stamp(source: str):
    """``(size, mtime_ns)`` of the file(s) of a model path (a Matrix Market set: of its folder), None for a
    catalog spec."""
    from ..modelfiles import is_model_path

    if not is_model_path(source):
        return None
    try:
        st = os.stat(source)
    except OSError:
        return None  # the build says what is wrong
    return (st.st_size, st.st_mtime_ns)


@functools.lru_cache(maxsize=4)
def _model_of(source: str, stamp):
    from ..models import catalog
    return catalog.parse(source)


model_of.cache_clear = _model_of.cache_clear


def stamp() -> dict:
    """``{"host", "pid", "created"}`` of a task's result (UTC, ISO 8601, seconds)."""
    return {"host": platform.node(), "pid": os.getpid(),
            "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}


def rom_payload(rom) -> dict:
    """A reduced model as plain data: its kind and its matrices (and its lift ``basis`` where it has one:
    the mode shapes of a ``modes`` scene need it)."""
    arrays = {f: np.asarray(getattr(rom, f)) for f in type(rom)._fields}
    if getattr(rom, "basis", None) is not None:
        arrays["basis"] = np.asarray(rom.basis)
    return {"kind": rom.kind, "arrays": arrays}


def rom_from_payload(payload: dict):
    """The reduced model of a :func:`rom_payload` (a :class:`~morsuite.rom.SecondOrderROM` or :class:`~morsuite.rom.FirstOrderROM`)."""
    from ..rom import FirstOrderROM, SecondOrderROM
    cls = {"second-order": SecondOrderROM, "first-order": FirstOrderROM}[payload["kind"]]
    rom = cls(*(payload["arrays"][f] for f in cls._fields))
    if payload["arrays"].get("basis") is not None:
        rom.basis = np.asarray(payload["arrays"]["basis"])
    return rom
