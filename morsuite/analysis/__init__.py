"""Frequency responses, errors and norms (data only, no plotting)."""

from .response import errors, freq_grid, sigma_max

__all__ = ["sigma_max", "errors", "freq_grid"]
