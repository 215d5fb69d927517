"""morsuite: model-order reduction of large sparse second-order index-3 systems.

    import morsuite as ms
    fom = ms.models.dsms(g=6000)
    res = ms.reducers.make("irka", fom).reduce(20)
    df = ms.analysis.errors(fom, res.rom, omega)
    ms.romfiles.save_rom(res.rom, "rom")        # rom.npz, rom.mat, rom.json (provenance)
    rom = ms.load_rom("rom.npz")                # the same matrices, bit for bit
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

__all__ = ["models", "linalg", "analysis", "reducers", "rom", "romfiles", "load_rom", "MorsuiteError", "InputError",
           "ShapeError", "ModelError", "OptionError", "FileFormatError", "SpecError",
           "SingularShiftError", "MemoryBudgetError", "MorsuiteWarning", "ConvergenceWarning",
           "RankWarning", "StabilityWarning", "DtypeWarning", "AccuracyWarning", "__version__"]

#: Subpackages imported on first attribute access: ``import morsuite`` stays cheap (no
#: scipy.sparse, pandas, matplotlib, control or dask) so that a command pays only for
#: what it uses, e.g. a fully cached ``morsuite run`` needs no model and draws nothing.
_LAZY = ("models", "linalg", "analysis", "reducers", "rom", "romfiles", "studies", "report", "utils", "cli")


def __getattr__(name):
    import importlib
    if name == "load_rom":  # morsuite.load_rom: romfiles.load_rom (checks and attaches the sidecar)
        fn = importlib.import_module(".romfiles", __name__).load_rom
        globals()[name] = fn
        return fn
    if name in _LAZY:
        mod = importlib.import_module(f".{name}", __name__)
        globals()[name] = mod
        return mod
    raise AttributeError(f"module 'morsuite' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY) | {"load_rom"})
