"""``python -m morsuite.bench --case JSON | --readme DIR``: the scaling child process, the README.

Running benchmarks is ``morsuite bench NAME`` (:mod:`morsuite.cli`).
"""

from __future__ import annotations

import argparse
import json


def main(argv=None) -> int:
    from .readme import write_readme
    from .scaling_case import CASE_RESULT_TAG, run_case

    ap = argparse.ArgumentParser(prog="python -m morsuite.bench")
    ap.add_argument("--case", help="JSON of one scaling case (see morsuite.bench.scaling_case.run_case); "
                                   "prints its result")
    ap.add_argument("--readme", metavar="DIR", help="write DIR/README.md summarising the benchmark JSONs in DIR")
    args = ap.parse_args(argv)
    if args.readme:
        print(write_readme(args.readme))
    if args.case:
        row = run_case(json.loads(args.case))
        print(CASE_RESULT_TAG + json.dumps(row, default=str), flush=True)
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
