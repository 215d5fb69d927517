"""Command line: ``morsuite run | reduce | list | info``."""

from __future__ import annotations

import argparse
import json
import sys


def main(argv=None):
    parser = argparse.ArgumentParser(prog="morsuite", description=__doc__)
    sub = parser.add_subparsers(dest="cmd", required=True)
    p_info = sub.add_parser("info", help="summary of a model")
    p_info.add_argument("model", help="catalog spec (dsms:g=6000) or .mat/.npz path")
    args = parser.parse_args(argv)
    from . import models
    if args.cmd == "info":
        print(json.dumps(models.parse(args.model).summary(), indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
