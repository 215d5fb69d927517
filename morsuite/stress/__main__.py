"""``python -m morsuite.stress``: the stress runner (:func:`morsuite.stress.run.main`)."""

import sys

from .run import main

sys.exit(main())
