"""Frequency responses, errors and norms; time-domain simulation (data only, no plotting)."""

from .response import errors, freq_grid, sigma_max
from .simulate import output_errors, simulate
from . import signals

__all__ = ["sigma_max", "errors", "freq_grid", "simulate", "output_errors", "signals"]
