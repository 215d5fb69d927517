"""On-disk artifact cache: npz for arrays, JSON for everything else, never pickle.

An entry is ``ROOT/KIND/KK/KEY.npz`` plus ``ROOT/KIND/KK/KEY.json``; the key is the
SHA-256 of the JSON of what determines the artifact (model identity, reducer,
every option value with defaults filled in, r or the frequency grid), the morsuite
version and a digest of morsuite's numerical source files (see :func:`code_digest`). Both files are
written atomically and the JSON last, so an entry exists only when complete: an
interrupted run leaves whole entries and resumes from them. A cached entry keeps
the timing (and host) of the run that made it.

Entries without arrays (the spec memo of :mod:`.memo`) are a JSON file alone:
:meth:`Cache.get_json`, :meth:`Cache.put_json`.
"""

from __future__ import annotations

import functools
import hashlib
import json
import warnings
from pathlib import Path

import numpy as np

from .. import __version__
from ..utils import atomic_path, atomic_write_text, to_plain as plain

__all__ = ["Cache", "cache_key", "code_digest", "source_digest"]


#: The numerical part of morsuite: a change in any of these files changes every cache key.
_NUMERICAL_SOURCES = ("models", "linalg", "reducers", "analysis", "rom.py", "errors.py")


@functools.lru_cache(maxsize=None)
def source_digest(*names: str) -> str:
    """SHA-256 of the named parts of morsuite's source (folders: every ``*.py`` in them),
    relative to the package, e.g. ``source_digest("report")``."""
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for name in names:
        p = root / name
        for f in sorted(p.rglob("*.py")) if p.is_dir() else [p]:
            if f.is_file():
                h.update(str(f.relative_to(root)).encode())
                h.update(f.read_bytes())
    return h.hexdigest()


def code_digest() -> str:
    """SHA-256 of morsuite's numerical source files.

    The version alone does not move while the package is developed (an editable
    install keeps 0.1.0 through many edits of a reducer); the digest makes sure an
    edited reducer never serves a stale cache entry. Studies, reports and the CLI
    are not part of it: they do not change what a reduction returns.
    """
    return source_digest(*_NUMERICAL_SOURCES)


def cache_key(kind: str, **material) -> str:
    """SHA-256 of ``kind``, ``material``, the morsuite version and :func:`code_digest`."""
    blob = json.dumps(plain({"kind": kind, "morsuite": __version__, "code": code_digest(), **material}),
                      sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()


class Cache:
    """Artifact store under ``root``; ``read=False`` recomputes (entries are then overwritten)."""

    def __init__(self, root, *, read: bool = True, write: bool = True):
        self.root = Path(root)
        self.read = bool(read)
        self.write = bool(write)

    def __repr__(self):
        return f"Cache({str(self.root)!r}, read={self.read}, write={self.write})"

    def _paths(self, kind, key):
        d = self.root / kind / key[:2]
        return d / f"{key}.npz", d / f"{key}.json"

    def get(self, kind: str, key: str):
        """``(arrays, meta)`` or None when absent, unreadable or not for this key."""
        if not self.read:
            return None
        npz, js = self._paths(kind, key)
        if not (js.is_file() and npz.is_file()):
            return None
        try:
            meta = json.loads(js.read_text())
            with np.load(npz, allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
        except (OSError, ValueError) as exc:
            warnings.warn(f"cache entry {js} is unreadable ({exc}); recomputing")
            return None
        if meta.get("key") != key:
            return None
        return arrays, meta

    def put(self, kind: str, key: str, arrays: dict, meta: dict) -> None:
        """Store ``arrays`` (an npz) and ``meta`` (JSON, with ``key`` added) under ``kind``/``key``.

        Both files are written atomically; nothing is written when ``write`` is False.
        """
        if not self.write:
            return
        npz, js = self._paths(kind, key)
        with atomic_path(npz, suffix=".npz") as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, **{k: np.asarray(v) for k, v in arrays.items()})
        atomic_write_text(js, json.dumps(plain({**meta, "key": key}), sort_keys=True))

    def get_json(self, kind: str, key: str):
        """The JSON entry ``kind``/``key`` (a dict) or None when absent, unreadable or not for this key."""
        if not self.read:
            return None
        js = self._paths(kind, key)[1]
        try:
            meta = json.loads(js.read_text())
        except (OSError, ValueError):
            return None
        return meta if isinstance(meta, dict) and meta.get("key") == key else None

    def put_json(self, kind: str, key: str, meta: dict) -> None:
        """Store a JSON-only entry ``meta`` (with ``key`` added), atomically; nothing when ``write`` is False."""
        if self.write:
            atomic_write_text(self._paths(kind, key)[1], json.dumps(plain({**meta, "key": key}), sort_keys=True))

    def has(self, kind: str, key: str) -> bool:
        """Whether both files of entry ``kind``/``key`` exist (whatever ``read`` says; nothing is parsed)."""
        npz, js = self._paths(kind, key)
        return npz.is_file() and js.is_file()
