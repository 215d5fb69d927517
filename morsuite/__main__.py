"""``python -m morsuite ARGS`` runs the ``morsuite`` command line (:func:`morsuite.cli.main`)."""

import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())
