"""Studies: TOML spec -> validated plan -> Dask task graph -> results folder.

    from morsuite.studies import run
    result = run("studies/paper_dsms.toml")          # results/paper_dsms/
    result.summary                                   # DataFrame (also summary.csv / .md)
    result.manifest["artifacts"]                     # everything computed or taken from the cache

Modules, in the order data flows through them (each imports only modules before it;
``tests/test_architecture.py`` checks that no import circle exists):

- validation: :mod:`.checks` (the failure format, value validators), the option tables
  :mod:`.norm_options` and :mod:`.time_options`, :mod:`.kinds` (scene kinds: keys, what
  each needs, output names), :mod:`.spec` (format and validation);
- planning: :mod:`.cache` (npz/JSON store), :mod:`.memo` (validated models and methods
  kept in the cache), :mod:`.plan` (artifacts, deduplicated);
- the graph's tasks: :mod:`.task_common` (what they share), :mod:`.tasks`, :mod:`.norms`,
  :mod:`.timedomain`; :mod:`.execute` (schedulers, progress);
- outputs: :mod:`.time_figures` and :mod:`.scenes` (figures and tables from results),
  :mod:`.results` (lookups, the summary), :mod:`.outputs` (figures and tables keyed by
  content, reused when unchanged), :mod:`.manifest`, :mod:`.environment`, :mod:`.pages`
  (the study's ``index.html`` and the results folder's);
- :mod:`.runner` (the whole run); :mod:`.batch` (several studies at once: what any of them
  lacks computed once on worker processes pinned to the cores, then each study's run; the
  command line's default); :mod:`.compare` (``morsuite compare``: a comparison study of one
  model, built in memory, written and run).

A re-run does nothing twice: results come from the cache, and figures and tables
whose data, style and software did not change are left as they are (``run(...,
rerender=True)``, ``morsuite run --rerender`` draws them all again).
"""

from .scenes import KINDS
from .spec import Study, load_spec, study_from_dict
from .plan import build_plan
from .runner import RunResult, run

__all__ = ["run", "RunResult", "load_spec", "study_from_dict", "Study", "build_plan", "KINDS"]
