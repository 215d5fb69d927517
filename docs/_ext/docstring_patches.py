"""Sphinx extension: reStructuredText fixes to docstrings of modules being edited elsewhere.

A few docstrings do not parse as reStructuredText (a ``|x|`` read as a
substitution, a simple table whose text runs into the column margin, ``\\nu``
in a non-raw string). Their modules were being changed on other branches when
the documentation was set up, so the fix is applied here, at build time, to
the docstring text autodoc reads, instead of in the source. Each patch names
one object and the exact text it replaces: nothing else is touched and no
warning is suppressed. Once the source is fixed the patch no longer matches;
it is then reported (``sphinx -v`` shows it) and should be deleted. Move these
fixes into the source when those modules are quiet.
"""

from __future__ import annotations

from sphinx.util import logging

logger = logging.getLogger(__name__)

_BT_TABLE_OLD = "===== ==================================== ==================================="
_BT_TABLE_NEW = "===== ===================================== ==================================="

_SCENES_OLD = """\
========== ===================================================== ===== =======
kind       shows                                                 grid  r
========== ===================================================== ===== =======
sigma      :math:`\\sigma_{\\max}(T(j\\omega))` of full and reduced yes   one
error      absolute (``error = "abs"``) or relative error         yes   one
compare    error of several methods at one r (BT vs IRKA)         yes   one
error_vs_r max error on the grid or ``h2_error_grid`` against r   yes   many
time_vs_r  reduction time against r                              no    many
pareto     time against error, one point per method and r        yes   many
convergence IRKA's shift change per iteration, one curve per r   no    many
hsv        Hankel singular values (methods that report ``hsv``)   no    one
table      summary table of the scene's reductions                yes   many
========== ===================================================== ===== ======="""

_SCENES_NEW = """\
=========== ====================================================== ===== =======
kind        shows                                                  grid  r
=========== ====================================================== ===== =======
sigma       :math:`\\sigma_{\\max}(T(j\\omega))` of full and reduced  yes   one
error       absolute (``error = "abs"``) or relative error         yes   one
compare     error of several methods at one r (BT vs IRKA)         yes   one
error_vs_r  max error on the grid or ``h2_error_grid`` against r   yes   many
time_vs_r   reduction time against r                               no    many
pareto      time against error, one point per method and r         yes   many
convergence IRKA's shift change per iteration, one curve per r     no    many
hsv         Hankel singular values (methods that report ``hsv``)   no    one
table       summary table of the scene's reductions                yes   many
=========== ====================================================== ===== ======="""

#: (object's full name, text as autodoc reads it, replacement, what was wrong)
PATCHES = [
    ("morsuite.analysis.timestep.march_index3", "[v_0; \nu]", "[v_0; \\nu]",
     "'\\nu' in a non-raw docstring is a newline and 'u'"),
    ("morsuite.linalg.saddle_lu.rcond_estimate", "``mag`` = |a||M| + |b||D| + |c||K|",
     "``mag = |a||M| + |b||D| + |c||K|``", "'|a|' is read as a substitution reference"),
    ("morsuite.linalg.saddle_lu.rcond_estimate", "the scales |s|^2 M and G", "the scales ``|s|^2 M`` and G",
     "'|s|' is read as a substitution reference"),
    ("morsuite.reducers.shift_update.shifts_from_poles", "1e-8 |alpha|", "1e-8 ``|alpha|``",
     "'|alpha|' is read as a substitution reference"),
    ("morsuite.reducers.bt", _BT_TABLE_OLD, _BT_TABLE_NEW,
     "the second column of the table of levels is one character too narrow for its 'pv' row"),
    ("morsuite.studies.scenes", _SCENES_OLD, _SCENES_NEW,
     "'convergence' is wider than the first column of the table of kinds"),
]


def _apply(app, what, name, obj, options, lines):
    patches = [p for p in PATCHES if p[0] == name]
    if not patches:
        return
    text = "\n".join(lines)
    for _, old, new, why in patches:
        if old in text:
            text = text.replace(old, new)
        else:
            logger.verbose("docstring patch for %s no longer applies (%s): delete it from %s",
                           name, why, __name__)
    lines[:] = text.split("\n")


def setup(app):
    # before numpydoc (priority 500), which parses the text into sections
    app.connect("autodoc-process-docstring", _apply, priority=400)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
