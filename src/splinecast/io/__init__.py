"""Reading and writing volumes, and synthetic test volumes.

>>> from splinecast.io import read, demo
>>> vol = read("demo:sphere?size=32")
>>> vol.shape
(32, 32, 32)

Every reader follows the convention of :mod:`splinecast.volume` (``data[i, j, k]`` with ``i`` along
x). Optional libraries (pynrrd, nibabel, pydicom, tifffile) are imported only by the reader that
needs them; ``pip install 'splinecast[io]'`` installs them all.
"""

from .dispatch import read, write
from .orientation import OrientationWarning
from .selection import SeveralVolumesWarning
from .synthetic import demo

__all__ = ["read", "write", "demo", "OrientationWarning", "SeveralVolumesWarning"]
