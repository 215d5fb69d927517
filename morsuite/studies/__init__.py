"""Studies: TOML spec -> validated plan -> Dask task graph -> results folder.

    from morsuite.studies import run
    result = run("studies/paper_dsms.toml")          # results/paper_dsms/
    result.summary                                   # DataFrame (also summary.csv / .md)
    result.manifest["artifacts"]                     # everything computed or taken from the cache

Modules: :mod:`.spec` (format and validation), :mod:`.memo` (validated models and
methods kept in the cache), :mod:`.scenes` (scene kinds: what each needs and
draws), :mod:`.plan` (artifacts, deduplicated), :mod:`.tasks` (the graph's
functions), :mod:`.cache` (npz/JSON store), :mod:`.execute` (schedulers,
progress), :mod:`.outputs` (figures and tables keyed by content, reused when
unchanged), :mod:`.manifest`, :mod:`.runner` (the whole run), :mod:`.environment`.

A re-run does nothing twice: results come from the cache, and figures and tables
whose data, style and software did not change are left as they are (``run(...,
rerender=True)``, ``morsuite run --rerender`` draws them all again).
"""

from .scenes import KINDS
from .spec import Study, load_spec, study_from_dict
from .plan import build_plan
from .runner import RunResult, run

__all__ = ["run", "RunResult", "load_spec", "study_from_dict", "Study", "build_plan", "KINDS"]
