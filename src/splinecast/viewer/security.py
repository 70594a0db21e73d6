"""Who may talk to the viewer: the token, the Host header and the WebSocket's Origin.

* **Token.** A random URL-safe token (:func:`new_token`) is part of the URL the server prints; the
  page and every static file carry it as ``?token=``, the WebSocket handshake too. Missing: 401;
  wrong: 403. Compared in constant time.
* **Host.** A page from any web site can make the browser send requests to ``127.0.0.1`` under a
  name the attacker controls (DNS rebinding); refusing every Host header that is not a local name
  (or the name the server was explicitly bound to) with the server's port stops that: 403.
* **Origin.** Browsers send the page's origin with a WebSocket handshake; only the viewer's own
  origin (a local name and the server's port) may open one: 403. Clients that are not browsers
  send no Origin and are let through on the token alone.

These are plain functions over header values so they can be tested without a server.
"""

from __future__ import annotations

import hmac
import ipaddress
import secrets
from urllib.parse import urlsplit

__all__ = ["LOCAL_NAMES", "new_token", "check_token", "allowed_hosts", "host_allowed",
           "origin_allowed", "is_loopback"]

#: Names under which a local server is reached.
LOCAL_NAMES = ("127.0.0.1", "localhost", "::1")


def new_token() -> str:
    """A fresh random token (192 bits, URL-safe)."""
    return secrets.token_urlsafe(24)


def check_token(given: str | None, token: str) -> int | None:
    """``None`` when ``given`` is the token, else the HTTP status to answer (401 or 403)."""
    if not given:
        return 401
    if not hmac.compare_digest(given.encode(), token.encode()):
        return 403
    return None


def is_loopback(host: str) -> bool:
    """Whether ``host`` (a name or address the server binds to) is on this machine only."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def allowed_hosts(bind_host: str, port: int) -> frozenset[str]:
    """The ``Host`` header values the server answers: local names, and the bound name when the
    server was explicitly bound elsewhere, each with the port."""
    names = set(LOCAL_NAMES)
    if bind_host not in ("", "0.0.0.0", "::"):
        names.add(bind_host)
    return frozenset(_with_port(name, port) for name in names)


def _with_port(name: str, port: int) -> str:
    name = name.lower()
    if ":" in name and not name.startswith("["):
        name = f"[{name}]"  # IPv6 literal
    return f"{name}:{port}"


def host_allowed(host: str | None, allowed: frozenset[str]) -> bool:
    """Whether a request's ``Host`` header is one of ``allowed``."""
    return host is not None and host.lower() in allowed


def origin_allowed(origin: str | None, allowed: frozenset[str]) -> bool:
    """Whether a WebSocket handshake's ``Origin`` is the viewer's own (absent: not a browser)."""
    if origin is None:
        return True
    try:
        parts = urlsplit(origin)
    except ValueError:
        return False
    if parts.scheme != "http" or parts.path not in ("", "/") or parts.query or parts.username:
        return False
    return parts.netloc.lower() in allowed
