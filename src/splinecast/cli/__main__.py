"""``python -m splinecast.cli``: the same as the ``splinecast`` command."""

import sys

from . import main

# The guard matters: worker processes of `splinecast movie --workers N` are spawned and import
# the main module again; they must not run the command line a second time.
if __name__ == "__main__":
    sys.exit(main())
