"""Argument checks shared by the norm functions (h2, hinf)."""

from __future__ import annotations

import warnings

import numpy as np

from ..errors import InputError, OptionError, StabilityWarning
from ..linalg.gramians import ADI_DEFAULTS
from ._rom import first_order_arrays

__all__ = ["check_fom", "adi_options", "validate_rom", "infinite"]


def check_fom(fom):
    from ..models.index3 import Index3Model

    if not isinstance(fom, Index3Model):
        raise InputError(f"fom must be an Index3Model; got {type(fom).__name__}")


def adi_options(adi) -> dict:
    """The ``adi`` argument as a dict of LR-ADI options (unknown names refused)."""
    if adi is None:
        return {}
    if not isinstance(adi, dict):
        raise OptionError(f"adi must be a dict of LR-ADI options; got {type(adi).__name__}")
    unknown = sorted(set(adi) - set(ADI_DEFAULTS))
    if unknown:
        raise OptionError(f"adi has unknown LR-ADI option(s) {', '.join(map(repr, unknown))}; valid: "
                          f"{', '.join(sorted(ADI_DEFAULTS))}")
    return dict(adi)


def validate_rom(fom, rom, name="rom"):
    """(E, A, B, C, D) of the reduced model, and None or (reason, warning class) when its error norm is infinite."""
    check_fom(fom)
    arrays = first_order_arrays(fom, rom, name)
    lam = rom.poles()
    if lam.size and not np.all(lam.real < 0):
        return arrays, (f"{name} is unstable ({int(np.sum(lam.real >= 0))} poles in the closed right half-plane, "
                        f"max real part {lam.real.max():.3e}): the error norm is infinite", StabilityWarning)
    return arrays, None


def flexible_route(fom, rom, fn, details, **options):
    """Free-floating models (:mod:`morsuite.models.rigid`): ``fn`` on the flexible parts of ``fom`` and
    ``rom``, where :math:`T - T_r` lives, with ``rigid_modes`` and ``part`` in the record; ``inf`` with
    a :class:`StabilityWarning` when ``rom`` does not carry the model's rigid part. None for a model
    without rigid-body modes (the caller goes on). Cost: the model's detection, once (cached)."""
    from ..errors import InputError, StabilityWarning
    from ..models.rigid import rigid_body_modes, split

    if not hasattr(fom, "cache") or not rigid_body_modes(fom).k:
        return None
    try:
        part_fom, part_rom, k = split(fom, rom)
    except InputError as exc:
        return infinite(str(exc), StabilityWarning, details, stacklevel=4)
    out = fn(part_fom, part_rom, details=details, **options)
    if details:
        out[1].update(rigid_modes=k, part="flexible")
    return out


def refuse_rigid(fom, what):
    """A model with rigid-body modes has a pole at 0: no finite norm; say so and name the flexible part."""
    from ..errors import InputError
    from ..models.rigid import rigid_body_modes

    if hasattr(fom, "cache") and rigid_body_modes(fom).k:
        raise InputError(f"fom: model {fom.name} has {rigid_body_modes(fom).k} rigid-body modes, a pole of T at "
                         f"s = 0: its norm is infinite; {what} of its flexible part: "
                         f"{what}(morsuite.models.rigid.flexible_part(fom))")


def infinite(reason, category, details, stacklevel=3):
    """``inf`` with a warning (and, with ``details``, a record saying why)."""
    warnings.warn(reason, category, stacklevel=stacklevel)
    if details:
        return np.inf, {"method": None, "value": np.inf, "reason": reason, "trusted": True, "lu_count": 0}
    return np.inf
