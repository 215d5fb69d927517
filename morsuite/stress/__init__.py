"""Stress suite: seeded random constrained models, invariant checks, outcome classes, refused inputs.

``python -m morsuite.stress --cases N --out results/stress`` runs N random
cases and writes ``summary.md`` and ``summary.csv``;
``python -m morsuite.stress --refused-table`` prints the table of
refused inputs. The property-based tests in ``tests/stress`` use the same
check functions.

Modules: :mod:`~morsuite.stress.cases` (random case draws),
:mod:`~morsuite.stress.reference` (equilibrated and dense references,
condition-scaled tolerances), :mod:`~morsuite.stress.checks` (invariants of
one run), :mod:`~morsuite.stress.replay` (invariants comparing two IRKA runs),
:mod:`~morsuite.stress.outcomes` (outcome classes, known bugs),
:mod:`~morsuite.stress.report` (summary files), :mod:`~morsuite.stress.run`
(the runner), :mod:`~morsuite.stress.refused` (the table of refused inputs).
Design notes and the findings of the 2000-case run: docs/design/stress.md.
"""

from .cases import (BT_MAXITER, FAMILIES, RUNNER_MAXIT, Case, draw_case, draw_model_params, given_shifts, regime,
                    transformed_g)
from .checks import (BT_BOUND_RTOL, CANCEL, HERMITE_TOL, N_GRID, NULLSPACE_TOL, bt_bound_of, check_bt_bound,
                     check_info_consistency, check_nullspace, check_reduction, hermite_error)
from .outcomes import (KNOWN_BUGS, OUTCOMES, SPURIOUS_KAPPA, CheckFailed, KnownBug, Outcome, attribute_silent,
                       classify_exception, known_bug)
from .reference import (KAPPA_REF, equilibrated_condition, equilibrated_saddle, nullspace_transfer, product_tol,
                        reference_response, reference_transfer, scaled_tol, sigma)
from .replay import AGREE_TOL, check_agreement, check_g_invariance
from .run import check_case, run_case, main

#: the names of the former module morsuite/stress.py first, then the other public names
__all__ = ["draw_model_params", "draw_case", "run_case", "reference_transfer", "equilibrated_condition",
           "check_reduction", "check_agreement", "check_nullspace", "check_g_invariance", "check_bt_bound",
           "hermite_error", "Outcome", "main", "FAMILIES", "OUTCOMES", "KAPPA_REF",
           "Case", "regime", "given_shifts", "transformed_g", "RUNNER_MAXIT", "BT_MAXITER",
           "reference_response", "nullspace_transfer", "equilibrated_saddle", "sigma", "scaled_tol", "product_tol",
           "check_info_consistency", "bt_bound_of", "check_case", "CheckFailed", "classify_exception", "KnownBug",
           "KNOWN_BUGS", "known_bug", "attribute_silent", "SPURIOUS_KAPPA", "HERMITE_TOL", "AGREE_TOL",
           "NULLSPACE_TOL", "BT_BOUND_RTOL", "N_GRID", "CANCEL"]
