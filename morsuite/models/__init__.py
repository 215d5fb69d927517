"""The full-order world: :class:`Index3Model`, generators, loaders, catalog."""

from .index3 import Index3Model
from .generators import dsms, tcom
from .fem import fem_beam, fem_block, eigenfrequencies
from .io import load, load_mat, load_mtx, load_npz, save_npz
from .catalog import available, get, parse, register
from .rigid import RigidModes, flexible_part, rigid_body_modes

__all__ = ["Index3Model", "dsms", "tcom", "fem_beam", "fem_block", "eigenfrequencies",
           "load", "load_mat", "load_mtx", "load_npz", "save_npz",
           "available", "get", "parse", "register", "RigidModes", "rigid_body_modes", "flexible_part"]
from .random import random_constrained; __all__.append("random_constrained")  # noqa: E402,E702
