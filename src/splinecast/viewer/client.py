"""A Python client of the viewer's WebSocket protocol (for scripts, tests and benchmarks).

>>> async def grab(url):                                    # doctest: +SKIP
...     async with ViewerClient(url) as client:
...         ident = await client.render({"mode": "mip", "size": [320, 240]})
...         frame = await client.frame(ident, final=True)
...         return frame.image                                  # uint8 (240, 320, 4)

The client follows ``docs/viewer-protocol.md``; it is what the browser page does, minus the page.
"""

from __future__ import annotations

import asyncio
import json
import time
from dataclasses import dataclass
from typing import Any
from urllib.parse import parse_qs, urlsplit

import numpy as np

from .encoding import decode_image
from .protocol import PROTOCOL_VERSION, unpack_frame

__all__ = ["ViewerClient", "ReceivedFrame", "ServerError"]


class ServerError(RuntimeError):
    """The server answered a request with an ``error`` message."""

    def __init__(self, message: dict[str, Any]) -> None:
        super().__init__(message.get("message"))
        self.message = message


@dataclass
class ReceivedFrame:
    """A frame message: its JSON header, the encoded image and when it arrived."""

    header: dict[str, Any]
    data: bytes
    received: float  # time.perf_counter() at arrival

    @property
    def image(self) -> np.ndarray:
        """The decoded image, RGBA uint8 ``(height, width, 4)``."""
        return decode_image(self.data)


class ViewerClient:
    """An open WebSocket to a viewer server.

    Parameters
    ----------
    url : str
        The page URL the server printed (``http://host:port/?token=...``).
    origin : str, optional
        An ``Origin`` header to send (browsers always send one; scripts need not).
    """

    def __init__(self, url: str, origin: str | None = None) -> None:
        parts = urlsplit(url)
        token = parse_qs(parts.query).get("token", [""])[0]
        self.ws_url = f"ws://{parts.netloc}/ws?token={token}"
        self.origin = origin
        self.hello: dict[str, Any] = {}
        #: Every ``error`` and ``status`` message received, in order.
        self.messages: list[dict[str, Any]] = []
        self._session: Any = None
        self._ws: Any = None
        self._next_id = 1
        self._sent: dict[int, float] = {}

    async def __aenter__(self) -> ViewerClient:
        import aiohttp

        self._session = aiohttp.ClientSession()
        headers = {"Origin": self.origin} if self.origin else None
        try:
            self._ws = await self._session.ws_connect(self.ws_url, headers=headers,
                                                      max_msg_size=0)
            self.hello = await self._ws.receive_json()
        except BaseException:
            await self._session.close()
            raise
        if self.hello.get("type") != "hello" or self.hello.get("v") != PROTOCOL_VERSION:
            raise RuntimeError(f"not a splinecast viewer (protocol {PROTOCOL_VERSION}): "
                               f"{str(self.hello)[:200]}")
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self._ws.close()
        await self._session.close()

    @property
    def ws(self) -> Any:
        """The underlying aiohttp WebSocket (to send raw or malformed messages)."""
        return self._ws

    def sent_at(self, ident: int) -> float:
        """``time.perf_counter()`` when request ``ident`` was sent."""
        return self._sent[ident]

    async def send(self, kind: str, state: dict[str, Any], interactive: bool = False) -> int:
        """Send a ``render`` or ``screenshot`` request; returns its id."""
        ident = self._next_id
        self._next_id += 1
        message = {"v": PROTOCOL_VERSION, "type": kind, "id": ident, "state": state,
                   "interactive": interactive}
        self._sent[ident] = time.perf_counter()
        await self._ws.send_str(json.dumps(message))
        return ident

    async def render(self, state: dict[str, Any], interactive: bool = False) -> int:
        """Ask for a frame of ``state``; returns the request id."""
        return await self.send("render", state, interactive)

    async def screenshot(self, state: dict[str, Any]) -> int:
        """Ask for a full-resolution PNG of ``state``; returns the request id."""
        return await self.send("screenshot", state)

    async def pick(self, state: dict[str, Any], x: float, y: float,
                   timeout: float = 600.0) -> dict[str, Any]:
        """Ask which label is under pixel ``(x, y)`` of ``state``'s image and wait for the
        answer: the ``pick`` message (``label``, ``name``, ``position``). Frames and other
        messages meanwhile are skipped; an ``error`` for it raises :class:`ServerError`."""
        ident = self._next_id
        self._next_id += 1
        self._sent[ident] = time.perf_counter()
        await self._ws.send_str(json.dumps({"v": PROTOCOL_VERSION, "type": "pick", "id": ident,
                                            "state": state, "x": x, "y": y}))
        deadline = time.perf_counter() + timeout
        while True:
            left = deadline - time.perf_counter()
            if left <= 0:
                raise TimeoutError(f"no pick answer for request {ident} within {timeout:g} s")
            got = await self.receive(left)
            if isinstance(got, dict) and got.get("id") == ident:
                if got.get("type") == "error":
                    raise ServerError(got)
                if got.get("type") == "pick":
                    return got

    async def receive(self, timeout: float = 600.0) -> ReceivedFrame | dict[str, Any]:
        """The next message: a :class:`ReceivedFrame` or a JSON message (dict)."""
        import aiohttp

        message = await asyncio.wait_for(self._ws.receive(), timeout)
        if message.type == aiohttp.WSMsgType.BINARY:
            header, data = unpack_frame(message.data)
            return ReceivedFrame(header, data, time.perf_counter())
        if message.type == aiohttp.WSMsgType.TEXT:
            parsed = json.loads(message.data)
            self.messages.append(parsed)
            return parsed
        raise ConnectionError(f"the server closed the connection ({message.type.name}, "
                              f"{message.data!r})")

    async def frame(self, ident: int, final: bool = True, timeout: float = 600.0
                    ) -> ReceivedFrame:
        """Wait for a frame of request ``ident`` (the final one unless ``final=False``).

        Frames of other requests are skipped. An ``error`` for ``ident`` raises
        :class:`ServerError`.
        """
        deadline = time.perf_counter() + timeout
        while True:
            left = deadline - time.perf_counter()
            if left <= 0:
                raise TimeoutError(f"no frame for request {ident} within {timeout:g} s")
            got = await self.receive(left)
            if isinstance(got, ReceivedFrame):
                if got.header["id"] == ident and (got.header["final"] or not final):
                    return got
            elif got.get("type") == "error" and got.get("id") == ident:
                raise ServerError(got)
