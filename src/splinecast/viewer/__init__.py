"""The interactive viewer in the browser: ``splinecast view FILE`` and ``sc.view(volume)``.

A local aiohttp server renders on the CPU and streams frames to a plain HTML/JavaScript page over
a WebSocket (reduced-resolution JPEG while the user drags, full-resolution PNG when input stops).
Modules, one concept each:

* :mod:`.state` - the render state a page sends, validated into a camera and render options;
* :mod:`.protocol` - the JSON/binary message protocol (``docs/viewer-protocol.md``);
* :mod:`.encoding` - frame images as JPEG or PNG bytes;
* :mod:`.data` - what is shown: the data given, classified, and what the page may choose;
* :mod:`.kinds` - what the viewer does differently per kind of data (one class per kind);
* :mod:`.renderer` - scenes per model, reduced-scale and striped renders;
* :mod:`.session` - per-client scheduling: newest request wins, settle, progressive passes;
* :mod:`.security` - token, Host and Origin checks;
* :mod:`.server` - the aiohttp application and its static files;
* :mod:`.handle` - :func:`view` and the notebook handle.

Importing this package does not import aiohttp; starting a server does.
"""

from .handle import ViewerHandle, view

__all__ = ["ViewerHandle", "view"]
