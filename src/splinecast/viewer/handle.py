"""``sc.view(...)`` from Python: the viewer server on a background thread, and a handle to it
that a Jupyter notebook shows inline.

The server runs its own asyncio event loop on a daemon thread, so the interpreter (or notebook
kernel) stays free; :meth:`ViewerHandle.stop` ends it. In a notebook the handle's
``_repr_html_`` is an ``<iframe>`` pointing at the tokened URL, so the viewer appears in the cell
that returned it.
"""

from __future__ import annotations

import asyncio
import html
import sys
import threading
import webbrowser
from typing import Any

from ..errors import ParameterError

__all__ = ["ViewerHandle", "view", "require_aiohttp"]

_START_TIMEOUT_S = 30.0


def require_aiohttp() -> None:
    """Raise a one-line install hint when the server library is missing."""
    try:
        import aiohttp  # noqa: F401
    except ImportError:
        raise ParameterError("the viewer needs aiohttp: pip install 'splinecast[viewer]'") from None


def _in_notebook() -> bool:
    """Whether we run inside a Jupyter kernel (then the handle displays inline instead)."""
    shell = sys.modules.get("IPython")
    if shell is None or "ipykernel" not in sys.modules:
        return False
    ip = shell.get_ipython()
    return ip is not None and getattr(ip, "kernel", None) is not None


class ViewerHandle:
    """A running viewer: its URL, a way to stop it, and an inline view for notebooks.

    Attributes
    ----------
    url : str
        The page's address, including its access token.
    server : ViewerServer
        The server object (for example to call ``refresh_all()``).
    """

    #: Height of the inline frame in a notebook, in CSS pixels.
    height = 640

    def __init__(self, server: Any, loop: asyncio.AbstractEventLoop,
                 thread: threading.Thread) -> None:
        self.server = server
        self.url: str = server.url
        self._loop = loop
        self._thread = thread

    @property
    def running(self) -> bool:
        """Whether the server thread is still serving."""
        return self._thread.is_alive()

    def stop(self, timeout: float = 10.0) -> None:
        """Close every connection and stop the server (idempotent)."""
        if not self._thread.is_alive():
            return
        future = asyncio.run_coroutine_threadsafe(self.server.stop(), self._loop)
        try:
            future.result(timeout)
        finally:
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(timeout)

    def wait(self) -> None:
        """Block until the server stops or Ctrl-C (for scripts that only show a viewer)."""
        try:
            while self._thread.is_alive():
                self._thread.join(0.5)
        except KeyboardInterrupt:
            self.stop()

    def _repr_html_(self) -> str:
        src = html.escape(self.url, quote=True)
        return (f'<iframe src="{src}" width="100%" height="{self.height}" '
                f'style="border:0" allow="clipboard-write" title="splinecast viewer"></iframe>'
                f'<div><a href="{src}" target="_blank" rel="noopener">open the viewer in a '
                f'new tab</a></div>')

    def __repr__(self) -> str:
        state = "running" if self.running else "stopped"
        return f"ViewerHandle({self.url!r}, {state})"


def view(data: Any, model: str | None = None, mode: str = "iso", iso: Any = None, *,
         host: str = "127.0.0.1", port: int = 0, open_browser: bool | None = None,
         max_pixels: int | None = None, budget: Any = None,
         lod: float | None = None, labels: bool = False,
         colors: Any = None) -> ViewerHandle:
    """Show a volume or scene in the interactive browser viewer.

    Parameters
    ----------
    data : Volume, Scene, MultiscaleVolume, MultiscaleScene, WaveletVolume or WaveletScene
        What to show. A pyramid or wavelet store (``sc.read("x.zarr")``) is rendered cut by cut;
        the page refines the image as bricks arrive and shows their counts. A multiresolution
        scene is shown with its own model only (and stays open after the viewer stops).
    model, mode, iso : optional
        Initial reconstruction, render mode and isovalue(s) (the page can change them).
    host : str
        Address to listen on (default: this machine only).
    port : int
        Port to listen on (default: any free port).
    open_browser : bool, optional
        Open the default web browser at the viewer's URL; by default yes, except inside a
        Jupyter notebook, where the returned handle shows the viewer in the cell.
    max_pixels : int, optional
        Largest image a page may request.
    budget : int or str, optional
        Brick cache of a pyramid volume (default ``"2GiB"``).
    lod : float, optional
        Level of detail of a pyramid volume (pixels per voxel, default 1) or a wavelet store (ε in
        radians, default one pixel's angle).
    labels : bool
        Show ``data`` (integer labels: a segmentation) as a label volume: each label its own
        coloured surface, a label list on the page and the label under the cursor (as
        ``Scene(data, labels=True)``; a ``LabelScene`` given as ``data`` is shown as it is).
    colors : path, mapping or list, optional
        With ``labels``: colours and names of labels (a colour table, as
        ``Scene(data, labels=True, colors=...)``).

    Returns
    -------
    ViewerHandle
        ``handle.url`` is the address; ``handle.stop()`` ends the server.

    Raises
    ------
    ParameterError
        Bad model, mode, isovalue or port; aiohttp missing; the port is taken.

    Examples
    --------
    >>> import splinecast as sc
    >>> vol = sc.demo("marschner-lobb", size=64)
    >>> handle = sc.view(vol, open_browser=False)  # doctest: +SKIP
    >>> handle.url  # doctest: +SKIP
    'http://127.0.0.1:40123/?token=...'
    >>> handle.stop()  # doctest: +SKIP
    """
    require_aiohttp()
    from .server import ViewerServer
    from .state import MAX_PIXELS

    server = ViewerServer(data, model=model, mode=mode, iso=iso, host=host, port=port,
                          max_pixels=max_pixels or MAX_PIXELS, budget=budget, lod=lod,
                          labels=labels, colors=colors)
    loop = asyncio.new_event_loop()
    started = threading.Event()
    failure: list[BaseException] = []

    def serve() -> None:
        asyncio.set_event_loop(loop)
        try:
            loop.run_until_complete(server.start())
        except BaseException as exc:  # reported to the caller below
            failure.append(exc)
            started.set()
            loop.close()
            return
        started.set()
        try:
            loop.run_forever()
        finally:
            loop.close()

    thread = threading.Thread(target=serve, name="splinecast-viewer", daemon=True)
    thread.start()
    if not started.wait(_START_TIMEOUT_S):
        raise ParameterError(f"the viewer did not start within {_START_TIMEOUT_S:g} s")
    if failure:
        server.renderer.close()  # a pyramid's loader thread
        raise failure[0]
    handle = ViewerHandle(server, loop, thread)
    if open_browser is None:
        open_browser = not _in_notebook()
    if open_browser:
        webbrowser.open(handle.url)
    return handle
