"""Reducers: one interface, a registry (``make``, ``available``), one module per method."""

from .base import Option, Reducer, Reduction, available, get_class, make, register
from .irka.second_order import IRKA
from .irka.projected import IRKAProjected  # noqa: F401  (registers "irka-projected")
from .bt.balanced import BT  # noqa: F401  (registers "bt")
from .bt.frequency_limited import BTFL  # noqa: F401  (registers "bt-fl")
from .irka.first_order import IRKAFO  # noqa: F401  (registers "irka-fo")
from .h2.so_h2 import SOH2  # noqa: F401  (registers "so-h2")
from .modal import Modal  # noqa: F401  (registers "modal")
from .krylov import Krylov  # noqa: F401  (registers "krylov")
from .adaptive import Adaptive  # noqa: F401  (registers "adaptive")
from .dominant import Dominant  # noqa: F401  (registers "dominant")

__all__ = ["Option", "Reducer", "Reduction", "make", "available", "register", "get_class", "IRKA"]
