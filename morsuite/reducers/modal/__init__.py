"""Modal truncation: constrained undamped modes (shift-invert Lanczos on one saddle LU) with an optional
static correction; the reducer ``"modal"`` (:class:`~morsuite.reducers.modal.reducer.Modal`) and its mode
selections (:mod:`~morsuite.reducers.modal.selection`)."""

from .reducer import Modal, SELECTIONS

__all__ = ["Modal", "SELECTIONS"]
