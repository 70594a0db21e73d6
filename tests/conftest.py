"""Suite-wide settings of the test run."""

from __future__ import annotations

import os

# The test run's workers share the cores (one per core), so a thread that waits for work must
# sleep, not spin: OpenMP's threads (Numba's parallel loops outside the frame loops) otherwise
# spin after every parallel region and take the CPU the other worker compiles on. Set before
# any parallel region runs (OpenMP reads it when it starts); a value given outside is kept.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
