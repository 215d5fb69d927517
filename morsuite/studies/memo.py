"""What validating a spec learnt, kept in the cache: a cached study needs no model.

Validating a spec builds each model once (to learn its name, order and band) and
imports the reducers (to check options against their tables and fill in the
defaults). Neither changes unless morsuite's numerical code does, and both cost
more than the rest of a fully cached run (scipy.sparse, the generators, the
reducers' imports). :class:`SpecMemo` keeps each result as a JSON entry of the
artifact cache, keyed like every entry by :func:`~morsuite.studies.cache.cache_key`
(morsuite version and code digest included): a model by its spec as written (a
file by its content), a method by reducer name and options as written.

Only morsuite's own models and reducers are memoised, and the memo is consulted
only while their registry module is not imported in this process: a model or
reducer registered at run time (which needs that import) is always validated
afresh, so a memo entry can never stand in for a registration it did not see.
"""

from __future__ import annotations

import sys

from .cache import Cache, cache_key

__all__ = ["SpecMemo"]


class SpecMemo:
    """Validated model and method entries in ``cache`` (a :class:`Cache` or its root).

    :meth:`store` only notes an entry; :meth:`flush` writes what was noted. The
    runner flushes when a study starts to run, so that validating specs (a dry run,
    or specs of which one is wrong) writes nothing.
    """

    def __init__(self, cache):
        self.cache = cache if isinstance(cache, Cache) else Cache(cache)
        self.pending = {}

    def __repr__(self):
        return f"SpecMemo({self.cache!r})"

    @staticmethod
    def _key(kind, material):
        try:
            return cache_key("spec-" + kind, **material)
        except (TypeError, ValueError):  # options TOML allows but JSON does not (dates): not memoised
            return None

    def lookup(self, kind: str, material: dict, registry: str):
        """The stored dict for ``material``, or None (also while ``registry`` is imported)."""
        if registry in sys.modules:
            return None
        key = self._key(kind, material)
        return None if key is None else self.cache.get_json("spec-" + kind, key)

    def store(self, kind: str, material: dict, value: dict, owner: str) -> None:
        """Keep ``value`` when ``owner`` (the factory's or class's module) is morsuite's own."""
        key = self._key(kind, material)
        if key is not None and owner.startswith("morsuite."):
            self.pending[("spec-" + kind, key)] = value

    def flush(self) -> None:
        """Write the noted entries (those already in the cache are left as they are)."""
        pending, self.pending = self.pending, {}
        for (kind, key), value in pending.items():
            if self.cache.get_json(kind, key) is None:
                self.cache.put_json(kind, key, value)
