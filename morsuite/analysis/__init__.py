"""Frequency responses, errors and norms; time-domain simulation (data only, no plotting)."""

from .response import band_response, errors, freq_grid, sigma_max
from ..norms.h2 import h2_error, h2_norm, h2_rel_error
from .hinf import hinf_error, hinf_norm, hinf_rel_error
from .simulate import output_errors, simulate
from . import signals
from .compare import error_norms
from . import compare
from .verify import verify_rom
from .modes import mac, match_modes, model_modes, rom_modes, structure_checks
from ..utils import worse_than_zero

__all__ = ["sigma_max", "errors", "freq_grid", "band_response", "h2_norm", "h2_error", "h2_rel_error", "hinf_norm", "hinf_error",
           "hinf_rel_error", "simulate", "output_errors", "signals", "error_norms", "compare",
           "worse_than_zero", "verify_rom", "model_modes", "rom_modes", "match_modes", "mac", "structure_checks"]
