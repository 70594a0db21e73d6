"""``python -m splinecast.cli``: the same as the ``splinecast`` command."""

import sys

from . import main

sys.exit(main())
