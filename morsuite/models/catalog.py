"""The model catalog: names, parameters and the ``model:key=value`` form.

``get("dsms", g=6000)``, ``parse("dsms:g=6000")``, or a path: a .mat or .npz
file or a Matrix Market set (``data/gyro``, ``./model_dir``; which strings are
paths: :func:`morsuite.modelfiles.is_model_path`). Every catalog model has a
default frequency band (``model.band``).
"""

from __future__ import annotations

import inspect
from pathlib import Path

from ..errors import InputError
from ..modelfiles import is_model_path
from .fem import fem_beam, fem_block
from .generators import dsms, tcom
from .index3 import Index3Model

__all__ = ["CATALOG", "get", "parse", "available"]

CATALOG = {"dsms": dsms, "tcom": tcom, "fem_beam": fem_beam, "fem_block": fem_block}


def available() -> list[str]:
    """Names of the catalog models (random_constrained included when present)."""
    return sorted(CATALOG)


def register(name: str, factory):
    """Add a model factory to the catalog (used by extensions and tests)."""
    CATALOG[name] = factory


def _params(factory):
    return [p for p in inspect.signature(factory).parameters.values()
            if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]


def get(name: str, **params) -> Index3Model:
    """Build catalog model ``name`` with keyword parameters.

    Unknown names and unknown parameters raise :class:`InputError` listing the
    valid choices.
    """
    if name not in CATALOG:
        raise InputError(f"unknown model {name!r}; available: {', '.join(available())}")
    factory = CATALOG[name]
    valid = [p.name for p in _params(factory)]
    bad = [k for k in params if k not in valid]
    if bad:
        raise InputError(f"model {name!r} has no parameter {', '.join(map(repr, bad))}; valid: {', '.join(valid)}")
    return factory(**params)


def _value(text: str):
    low = text.lower()
    if low in ("true", "false"):
        return low == "true"
    try:
        return int(text)
    except ValueError:
        pass
    try:
        v = float(text)
        # "6e3" means the integer 6000 (sizes are written that way on command lines)
        return int(v) if ("e" in low and v.is_integer() and abs(v) < 2**53) else v
    except ValueError:
        pass
    if ";" in text:
        return tuple(_value(t) for t in text.split(";"))
    return text


def parse(spec: str) -> Index3Model:
    """Model from ``"name"``, ``"name:key=value,key=value"`` or a path.

    Parameter values are parsed as int, float, bool, or a ``;``-separated tuple.
    A path (a .mat, .npz or .mtx file, a Matrix Market set's directory or stem)
    is read by :func:`morsuite.models.load` with its default options.
    """
    if not isinstance(spec, str) or not spec:
        raise InputError(f"model spec must be a non-empty string; got {spec!r}")
    if is_model_path(spec):
        from .io import load
        return load(Path(spec))
    name, _, rest = spec.partition(":")
    params = {}
    if rest:
        for item in rest.split(","):
            if not item:
                continue
            key, eq, val = item.partition("=")
            if not eq or not key:
                raise InputError(f"model spec {spec!r}: expected key=value, got {item!r}")
            params[key.strip()] = _value(val.strip())
    return get(name, **params)


def canonical(spec: str) -> str:
    """Canonical text of a catalog spec (sorted keys), used in cache keys."""
    if is_model_path(spec):
        return str(Path(spec))
    name, _, rest = spec.partition(":")
    items = sorted(i for i in rest.split(",") if i)
    return name + (":" + ",".join(items) if items else "")

from .random import random_constrained; register("random", random_constrained)  # noqa: E402,E702
