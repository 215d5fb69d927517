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

__all__ = ["models", "linalg", "analysis", "reducers", "rom", "MorsuiteError", "InputError",
           "ShapeError", "ModelError", "OptionError", "FileFormatError", "SpecError",
           "SingularShiftError", "MemoryBudgetError", "MorsuiteWarning", "ConvergenceWarning",
           "RankWarning", "StabilityWarning", "DtypeWarning", "AccuracyWarning", "__version__"]

#: Subpackages imported on first attribute access: ``import morsuite`` stays cheap (no
#: scipy.sparse, pandas, matplotlib, control or dask) so that a command pays only for
#: what it uses, e.g. a fully cached ``morsuite run`` needs no model and draws nothing.
_LAZY = ("models", "linalg", "analysis", "reducers", "rom", "studies", "report", "utils", "cli")


def __getattr__(name):
    if name in _LAZY:
        import importlib
        mod = importlib.import_module(f".{name}", __name__)
        globals()[name] = mod
        return mod
    raise AttributeError(f"module 'morsuite' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
