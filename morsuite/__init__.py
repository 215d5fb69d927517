"""morsuite: model-order reduction of large sparse second-order index-3 systems.

    import morsuite as ms
    fom = ms.models.dsms(g=6000)
    res = ms.reducers.make("irka", fom).reduce(20)
    df = ms.analysis.errors(fom, res.rom, omega)
"""

__version__ = "0.1.0"

from .errors import (  # noqa: E402
    AccuracyWarning,
    ConvergenceWarning,
    DtypeWarning,
    FileFormatError,
    InputError,
    MemoryBudgetError,
    ModelError,
    MorsuiteError,
    MorsuiteWarning,
    OptionError,
    RankWarning,
    ShapeError,
    SingularShiftError,
    SpecError,
    StabilityWarning,
)
from . import models, linalg, analysis  # noqa: E402,F401

__all__ = ["models", "linalg", "analysis", "reducers", "rom", "MorsuiteError", "InputError",
           "ShapeError", "ModelError", "OptionError", "FileFormatError", "SpecError",
           "SingularShiftError", "MemoryBudgetError", "MorsuiteWarning", "ConvergenceWarning",
           "RankWarning", "StabilityWarning", "DtypeWarning", "AccuracyWarning", "__version__"]


def __getattr__(name):  # lazy: reducers and rom import control (slow)
    if name in ("reducers", "rom", "studies", "report"):
        import importlib
        mod = importlib.import_module(f".{name}", __name__)
        globals()[name] = mod
        return mod
    raise AttributeError(f"module 'morsuite' has no attribute {name!r}")
