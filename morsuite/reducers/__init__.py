"""Reducers: one interface (:mod:`.base`), a registry (:mod:`.registry`: ``make``, ``available``,
``describe``, ``methods``), one folder per family, found by being there.

``ms.reducers.IRKA``, ``ms.reducers.BT``, ...: every registered reducer class is also an attribute
of this package under its class name (looked up in the registry on first use).
"""

from .base import Option, Reducer, Reduction
from .registry import Description, Method, Variant, available, describe, get_class, make, method, methods, register

__all__ = ["Option", "Reducer", "Reduction", "Description", "Variant", "Method", "make", "available", "register",
           "get_class", "describe", "methods", "method"]


def __getattr__(name):
    if name[:1].isupper():
        for reducer in available():
            cls = get_class(reducer)
            if cls.__name__ == name:
                return cls
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
