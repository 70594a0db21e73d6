"""Reading volumes over HTTP(S), S3 and Google Cloud Storage: OME-Zarr stores and single files.

A URL (``https://host/data/x.ome.zarr``, ``s3://bucket/x.zarr``, ``gs://bucket/head.nii.gz``)
is kept as text from end to end: it never becomes a :class:`pathlib.Path`, whose normalisation
would collapse its ``//``. The filesystem layer is fsspec (HTTP through aiohttp, S3 through
s3fs, GCS through gcsfs); a Zarr hierarchy is opened by zarr-python through a subclass of its
``FsspecStore`` whose every read comes here first, and voxels are read by
:mod:`.zarr_chunks`, with the same bounded decoding as for local stores.

What every request goes through (:class:`Remote`):

- a per-attempt time-out, retries with exponential back-off and jitter for what may pass (a
  5xx or 429 answer, a reset connection, a truncated body, a time-out), and a total deadline
  per request; 401, 403 and 404 are not retried;
- a byte cap: a whole chunk is asked for with ``Range: bytes=0-<cap>``, so a file larger than
  its chunk can be once encoded is recognised after ``cap + 1`` bytes, and a ``Content-Length``
  above the cap is refused before the body is read at all; metadata files are capped at
  :data:`~splinecast.errors.limits.MAX_JSON_BYTES` and validated as JSON;
- store keys from metadata checked to stay inside the store (no ``..``, no absolute or
  ``scheme://`` key, no backslash or control character), and HTTP redirects followed only to
  the same host (others listed in ``SPLINECAST_REMOTE_REDIRECT_HOSTS``), never to another
  scheme: no local file is ever reached from a remote store;
- one :class:`~splinecast.errors.ReadError` line naming the URL (user name and password
  removed) for a refusal, 401/403/404, a time-out or exhausted retries.

Many requests are in flight at once (:meth:`Remote.fetch_many`, bounded by
``SPLINECAST_REMOTE_CONCURRENCY``). The byte ranges a batch wants from one file (the inner chunks
of a shard) are merged into few requests (:func:`coalesce`, :meth:`Remote.fetch_ranges`): over a
network each request costs a round trip, and a shard's neighbouring chunks lie side by side in
it. A shard's index and size come from one suffix range request (:meth:`Remote.fetch_tails`,
HTTP; a HEAD and a range where the server does not answer suffix ranges), shared by the reads
that want it at once. A scene's brick loader makes several reads at once
(``SPLINECAST_REMOTE_READS``, see :mod:`splinecast.multires.store.cache`). Fetched chunk bytes
can be kept in a bounded local disk
cache (:class:`DiskCache`, ``SPLINECAST_CACHE_DIR`` and ``SPLINECAST_CACHE_SIZE``), least
recently used first out. Cached bytes are decoded with the same bounds as fresh ones.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import os
import random
import re
import shutil
import tempfile
import threading
import time
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import quote, unquote, urljoin, urlsplit, urlunsplit

from ..errors import ReadError, limits
from . import cancel

__all__ = [
    "DiskCache",
    "Remote",
    "RemoteSettings",
    "RemoteSource",
    "check_url",
    "coalesce",
    "is_url",
    "download",
    "open_remote_group",
    "redact",
]

#: URL schemes read, and the fsspec protocol of each.
SCHEMES = {"http": "http", "https": "https", "s3": "s3", "gs": "gcs", "gcs": "gcs"}
ENV_ANON = "SPLINECAST_REMOTE_ANON"
ENV_CACHE_DIR = "SPLINECAST_CACHE_DIR"
ENV_CACHE_SIZE = "SPLINECAST_CACHE_SIZE"
ENV_TIMEOUT = "SPLINECAST_REMOTE_TIMEOUT"
ENV_DEADLINE = "SPLINECAST_REMOTE_DEADLINE"
ENV_RETRIES = "SPLINECAST_REMOTE_RETRIES"
ENV_CONCURRENCY = "SPLINECAST_REMOTE_CONCURRENCY"
ENV_READS = "SPLINECAST_REMOTE_READS"
ENV_REDIRECT_HOSTS = "SPLINECAST_REMOTE_REDIRECT_HOSTS"
ENV_COALESCE_GAP = "SPLINECAST_REMOTE_COALESCE_GAP"
ENV_COALESCE_BYTES = "SPLINECAST_REMOTE_COALESCE_BYTES"
#: Zarr metadata file names (v2, v3, consolidated): small JSON, validated before zarr sees it.
_METADATA = frozenset(("zarr.json", ".zgroup", ".zarray", ".zattrs", ".zmetadata"))
_MAX_REDIRECTS = 5
#: Bytes per request when a single file is downloaded (several in flight).
_FILE_BLOCK = 8 << 20
_URL_RE = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*://")
_CONTROL = re.compile(r"[\x00-\x20\x7f]")


# --------------------------------------------------------------------------- URLs
def is_url(text: Any) -> bool:
    """``True`` for text of the form ``scheme://...`` (whatever the scheme: an unknown one is
    refused later by :func:`check_url`, with a message, rather than read as a local path)."""
    return isinstance(text, str) and bool(_URL_RE.match(text))


def redact(url: str) -> str:
    """``url`` without user name and password (they are never printed)."""
    try:
        parts = urlsplit(url)
    except ValueError:
        return limits.shorten(url, 120)
    if "@" not in parts.netloc:
        return url
    host = parts.netloc.rsplit("@", 1)[1]
    return urlunsplit((parts.scheme, "***@" + host, parts.path, parts.query, parts.fragment))


def _shown(url: str) -> str:
    text = redact(url)
    return text if len(text) <= 160 else text[:157] + "..."


def check_url(url: str) -> str:
    """The URL of a remote volume, checked and without a trailing ``/``.

    Raises
    ------
    ReadError
        Naming the URL: an unknown scheme (``file://`` included: local data is read by path),
        no host or bucket, a bad port, spaces or control characters, a query or fragment, or
        a user name or password inside the URL (pass credentials through the environment or
        ``storage_options``).
    """
    shown = _shown(url)
    try:
        parts = urlsplit(url)
        port = parts.port
    except ValueError as exc:
        raise ReadError(f"{shown}: malformed URL ({exc})") from None
    scheme = parts.scheme.lower()
    if scheme == "file":
        raise ReadError(f"{shown}: file:// URLs are not read; give the local path instead")
    if scheme not in SCHEMES:
        raise ReadError(f"{shown}: unknown URL scheme {scheme[:20]}:// (read are http://, "
                        "https://, s3:// and gs://)")
    if _CONTROL.search(url):
        raise ReadError(f"{shown}: malformed URL (spaces or control characters; percent-encode "
                        "them)")
    if "@" in parts.netloc:
        raise ReadError(f"{shown}: credentials inside the URL are not accepted; use the "
                        "environment, the usual configuration files or storage_options")
    host = parts.hostname
    if not host:
        what = "bucket" if scheme in ("s3", "gs", "gcs") else "host"
        raise ReadError(f"{shown}: malformed URL (no {what})")
    if port is not None and not 0 < port < 65536:
        raise ReadError(f"{shown}: malformed URL (port {port})")
    if parts.query or parts.fragment:
        raise ReadError(f"{shown}: a query or fragment in the URL is not supported")
    path = parts.path.rstrip("/")
    if any(p in (".", "..") for p in unquote(path).split("/")):
        raise ReadError(f"{shown}: malformed URL ('.' or '..' in its path)")
    return urlunsplit((scheme, parts.netloc, path, "", ""))


def _basename(url: str) -> str:
    return unquote(urlsplit(url).path.rstrip("/").rsplit("/", 1)[-1])


def _check_key(key: str, root: str) -> str:
    """A store key that stays inside the store (keys come from metadata: a dataset path)."""
    parts = key.split("/")
    if (not key or key.startswith("/") or "\\" in key or _CONTROL.search(key) or "://" in key
            or any(p in ("", ".", "..") for p in parts)):
        raise ReadError(f"{redact(root)}: the path {limits.shorten(key, 80)!r} leaves the store "
                        "or is not a store key; refused")
    return key


# --------------------------------------------------------------------------- settings
def _env_number(name: str, default: float, lo: float, hi: float) -> float:
    text = os.environ.get(name, "").strip()
    if not text:
        return default
    try:
        value = float(text)
    except ValueError:
        raise ReadError(f"{name}={limits.shorten(text)} is not a number") from None
    if not lo <= value <= hi:
        raise ReadError(f"{name}={text} must be within {lo:g}..{hi:g}")
    return value


def _env_bytes(name: str, default: int) -> int:
    """A byte count (``"256KiB"``) from the environment; ``0`` is accepted (off)."""
    text = os.environ.get(name, "").strip()
    if not text:
        return default
    if text == "0":
        return 0
    try:
        return limits.parse_bytes(text, name)
    except Exception:
        raise ReadError(f"{name}={limits.shorten(text)} is not a byte count (such as "
                        "256KiB, or 0)") from None


@dataclass(frozen=True)
class RemoteSettings:
    """How requests are made; defaults from the environment (:meth:`from_env`).

    Attributes
    ----------
    timeout : float
        Seconds one attempt may take (connecting, then between bytes received).
    deadline : float
        Seconds one request may take with all its retries.
    retries : int
        Attempts after the first, for failures that may pass.
    backoff : float
        Seconds before the first retry; doubled at each (with jitter).
    concurrency : int
        Requests in flight at once, per read.
    reads : int
        Reads a brick loader makes at once (each a batch of sibling bricks, its requests in
        flight together): over a network a read mostly waits for its round trips.
    redirect_hosts : tuple of str
        Hosts an HTTP redirect may lead to besides the store's own.
    anon : bool or None
        Anonymous access; ``None``: anonymous unless credentials are configured.
    cache_dir : str or None
        Folder of the disk cache of fetched chunks (none by default).
    cache_bytes : int
        Most bytes the disk cache holds.
    coalesce_gap : int
        Most bytes between two byte ranges of one file that one request still fetches together
        (the bytes between are fetched and dropped).
    coalesce_bytes : int
        Most bytes one merged request asks for (0: every range is its own request).
    """

    timeout: float = 30.0
    deadline: float = 120.0
    retries: int = 4
    backoff: float = 0.1
    concurrency: int = 32
    # Over a 50 ms link a read of a batch is two or three round trips, so eight reads at once
    # keep the link busy without holding many batches' buffers (bounded by the budget too).
    reads: int = 8
    redirect_hosts: tuple[str, ...] = ()
    anon: bool | None = None
    cache_dir: str | None = None
    cache_bytes: int = 2 << 30
    # A round trip costs what tens of kilobytes of transfer cost on a slow link and megabytes
    # on a fast one: a small gap is always worth fetching; the cap keeps a merged answer short
    # enough that several shards' requests still share the bandwidth in parallel.
    coalesce_gap: int = 256 << 10
    coalesce_bytes: int = 8 << 20

    @classmethod
    def from_env(cls) -> RemoteSettings:
        """Settings from ``SPLINECAST_REMOTE_*`` and ``SPLINECAST_CACHE_*`` (the command line's
        ``--anon``, ``--cache-dir`` and ``--cache-size`` set these)."""
        anon_text = os.environ.get(ENV_ANON, "").strip().lower()
        hosts = tuple(h.strip().lower() for h in
                      os.environ.get(ENV_REDIRECT_HOSTS, "").split(",") if h.strip())
        size = os.environ.get(ENV_CACHE_SIZE, "").strip()
        return cls(
            timeout=_env_number(ENV_TIMEOUT, 30.0, 0.01, 3600.0),
            deadline=_env_number(ENV_DEADLINE, 120.0, 0.01, 86400.0),
            retries=int(_env_number(ENV_RETRIES, 4, 0, 20)),
            concurrency=int(_env_number(ENV_CONCURRENCY, 32, 1, 1024)),
            reads=int(_env_number(ENV_READS, 8, 1, 256)),
            redirect_hosts=hosts,
            anon=True if anon_text in ("1", "true", "yes") else None,
            cache_dir=os.environ.get(ENV_CACHE_DIR) or None,
            cache_bytes=limits.parse_bytes(size, ENV_CACHE_SIZE) if size else 2 << 30,
            coalesce_gap=_env_bytes(ENV_COALESCE_GAP, 256 << 10),
            coalesce_bytes=_env_bytes(ENV_COALESCE_BYTES, 8 << 20),
        )


# --------------------------------------------------------------------------- disk cache
class DiskCache:
    """Fetched bytes kept in a local folder, at most ``max_bytes``, least recently used out.

    Files are named by a hash of what was asked (URL and byte range) and written to a temporary
    name, then renamed, so that concurrent processes sharing the folder see whole files only.
    The folder is created private (mode 0700). Every use touches a file's modification time,
    which orders eviction.
    """

    def __init__(self, folder: str | os.PathLike[str], max_bytes: int) -> None:
        self.folder = Path(folder)
        self.max_bytes = int(max_bytes)
        try:
            self.folder.mkdir(mode=0o700, parents=True, exist_ok=True)
        except OSError as exc:
            raise ReadError(f"{folder}: cannot create the cache folder: "
                            f"{exc.strerror or exc}") from None
        self._lock = threading.Lock()
        self._bytes = sum(f.stat().st_size for f in self._files())
        self.hits = 0
        self.misses = 0

    def _files(self) -> list[Path]:
        return [f for f in self.folder.glob("*/*") if f.is_file() and not f.name.startswith(".")]

    def _file(self, ident: str) -> Path:
        digest = hashlib.sha256(ident.encode()).hexdigest()
        return self.folder / digest[:2] / digest[2:]

    def get(self, ident: str) -> bytes | None:
        """The bytes kept for ``ident``, or ``None``."""
        path = self._file(ident)
        try:
            data = path.read_bytes()
            os.utime(path)
        except OSError:
            self.misses += 1
            return None
        self.hits += 1
        return data

    def put(self, ident: str, data: bytes) -> None:
        """Keep ``data`` (nothing if larger than the whole cache); evict the oldest beyond it."""
        if len(data) > self.max_bytes:
            return
        path = self._file(ident)
        try:
            path.parent.mkdir(mode=0o700, exist_ok=True)
            fd, temp = tempfile.mkstemp(dir=path.parent, prefix=".part-")
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
            os.replace(temp, path)
        except OSError:
            return  # a full or read-only disk costs a refetch, not the read
        with self._lock:
            self._bytes += len(data)
            if self._bytes > self.max_bytes:
                self._evict()

    def _evict(self) -> None:
        entries = []
        for f in self._files():
            with contextlib.suppress(OSError):
                info = f.stat()
                entries.append((info.st_mtime_ns, info.st_size, f))
        entries.sort()
        total = sum(size for _, size, _ in entries)
        target = int(self.max_bytes * 0.9)  # some room, so that eviction is not per put
        for _, size, f in entries:
            if total <= target:
                break
            with contextlib.suppress(OSError):
                f.unlink()
                total -= size
        self._bytes = total


_CACHES: dict[tuple[str, int], DiskCache] = {}


def _disk_cache(settings: RemoteSettings) -> DiskCache | None:
    if not settings.cache_dir:
        return None
    key = (os.path.abspath(settings.cache_dir), settings.cache_bytes)
    if key not in _CACHES:
        _CACHES[key] = DiskCache(key[0], settings.cache_bytes)
    return _CACHES[key]


# --------------------------------------------------------------------------- merging ranges
def coalesce(ranges: Sequence[tuple[int, int]], max_gap: int, max_bytes: int
             ) -> tuple[list[tuple[int, int]], list[int]]:
    """Merge byte ranges ``[start, stop)`` of one file into few spans.

    Ranges taken by their start are joined to the span before while the gap to it is at most
    ``max_gap`` bytes and the span stays at most ``max_bytes`` long; a range longer than that
    is a span of its own (``max_bytes`` 0: no merging). Overlapping ranges join too.

    Returns
    -------
    spans : list of (int, int)
        ``[start, stop)`` of each span, in file order.
    owner : list of int
        For each range (in the order given), the span that holds it whole.
    """
    order = sorted(range(len(ranges)), key=lambda i: ranges[i])
    spans: list[list[int]] = []
    owner = [0] * len(ranges)
    for i in order:
        a, b = (int(v) for v in ranges[i])
        if spans:
            last = spans[-1]
            stop = max(b, last[1])
            if a - last[1] <= max_gap and stop - last[0] <= max_bytes:
                last[1] = stop
                owner[i] = len(spans) - 1
                continue
        spans.append([a, b])
        owner[i] = len(spans) - 1
    return [(a, b) for a, b in spans], owner


# --------------------------------------------------------------------------- requests
class _Missing(Exception):
    """404 or 410: the key does not exist (zarr: fill value; a file: an error)."""


class _Transient(Exception):
    """A failure that may pass on another attempt."""


class _NoSuffix(Exception):
    """The server does not answer a suffix range (``bytes=-n``) with the file's last bytes and
    its size: the size is asked for on its own instead."""


_CONTENT_RANGE = re.compile(r"^bytes (\d{1,20})-(\d{1,20})/(\d{1,20})$")


def _credentials_configured(protocol: str) -> bool:
    """Whether the usual environment or configuration files give credentials (checked without
    any request: asking a cloud metadata service would stall for seconds off the cloud)."""
    env = os.environ
    home = Path.home()
    if protocol == "s3":
        return (any(env.get(v) for v in ("AWS_ACCESS_KEY_ID", "AWS_PROFILE",
                                          "AWS_WEB_IDENTITY_TOKEN_FILE",
                                          "AWS_CONTAINER_CREDENTIALS_RELATIVE_URI",
                                          "AWS_CONTAINER_CREDENTIALS_FULL_URI"))
                or Path(env.get("AWS_SHARED_CREDENTIALS_FILE", home / ".aws/credentials")).is_file()
                or Path(env.get("AWS_CONFIG_FILE", home / ".aws/config")).is_file())
    if protocol == "gcs":
        return bool(env.get("GOOGLE_APPLICATION_CREDENTIALS")) or (
            home / ".config/gcloud/application_default_credentials.json").is_file()
    return False


async def _gather(token: cancel.CancelToken | None, coros: list[Any]) -> list[Any]:
    """Run ``coros`` concurrently: on the first failure the others are cancelled; cancelling
    ``token`` (from another thread) cancels them all and raises :class:`.cancel.ReadCancelled`."""
    loop = asyncio.get_running_loop()
    tasks = [asyncio.ensure_future(c) for c in coros]

    def stop() -> None:  # called by the cancelling thread
        loop.call_soon_threadsafe(lambda: [task.cancel() for task in tasks])

    with token.hook(stop) if token is not None else contextlib.nullcontext():
        try:
            return list(await asyncio.gather(*tasks))
        except BaseException:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            if token is not None and token.cancelled:
                raise cancel.ReadCancelled() from None
            raise


def _zarr_loop_sync(coro: Any) -> Any:
    """Run ``coro`` on zarr-python's event loop (where the fsspec filesystem lives)."""
    from zarr.core.sync import sync

    return sync(coro)


_FILESYSTEMS: dict[tuple[str, str, float], Any] = {}
_FS_LOCK = threading.Lock()


def _filesystem(protocol: str, settings: RemoteSettings,
                storage_options: dict[str, Any] | None) -> Any:
    """One filesystem (one connection pool) per protocol, options and settings, shared by every
    store and file opened with them; their sessions are closed at exit."""
    key = (protocol, repr(sorted((storage_options or {}).items())) + repr(settings.anon),
           settings.timeout)
    with _FS_LOCK:
        fs = _FILESYSTEMS.get(key)
        if fs is None or getattr(fs, "_splinecast_pid", None) != os.getpid():
            fs = _make_filesystem(protocol, settings, storage_options)
            fs._splinecast_pid = os.getpid()  # a forked child makes its own (new event loop)
            if not _FILESYSTEMS:
                import atexit

                atexit.register(_close_filesystems)
            _FILESYSTEMS[key] = fs
    return fs


def _close_filesystems() -> None:
    """Close the filesystems' sessions on zarr's loop (else aiohttp warns at exit)."""
    async def close(fs: Any) -> None:
        with contextlib.suppress(Exception):
            session = getattr(fs, "_session", None)
            if session is not None and hasattr(session, "close"):
                await session.close()
            client = getattr(fs, "_s3", None)
            if client is not None:
                await client.__aexit__(None, None, None)

    mine = [fs for fs in _FILESYSTEMS.values() if getattr(fs, "_splinecast_pid", 0) == os.getpid()]
    _FILESYSTEMS.clear()
    if mine:
        with contextlib.suppress(Exception):
            _zarr_loop_sync(asyncio.gather(*(close(fs) for fs in mine)))


def _make_filesystem(protocol: str, settings: RemoteSettings,
                     storage_options: dict[str, Any] | None) -> Any:
    """An asynchronous fsspec filesystem for ``protocol`` with time-outs set."""
    from ._common import require

    fsspec = require("fsspec", "remote data", action="reading")
    options = dict(storage_options or {})
    if protocol in ("http", "https"):
        aiohttp = require("aiohttp", "remote data", action="reading")
        client = dict(options.pop("client_kwargs", {}) or {})
        client.setdefault("timeout", aiohttp.ClientTimeout(
            total=None, connect=settings.timeout, sock_read=settings.timeout))
        return fsspec.filesystem("http", asynchronous=True, skip_instance_cache=True,
                                 client_kwargs=client, **options)
    if protocol == "s3":
        require("s3fs", "remote data", action="reading")
        if settings.anon:
            options["anon"] = True
        elif "anon" not in options and not any(k in options for k in ("key", "secret",
                                                                        "token", "profile")):
            options["anon"] = not _credentials_configured("s3")
        config = dict(options.pop("config_kwargs", {}) or {})
        config.setdefault("connect_timeout", settings.timeout)
        config.setdefault("read_timeout", settings.timeout)
        # Retries are ours (with the deadline); botocore's own would multiply them.
        config.setdefault("retries", {"max_attempts": 1, "mode": "standard"})
        endpoint = os.environ.get("AWS_ENDPOINT_URL_S3") or os.environ.get("AWS_ENDPOINT_URL")
        if endpoint and "endpoint_url" not in options:
            options["endpoint_url"] = endpoint
        return fsspec.filesystem("s3", asynchronous=True, skip_instance_cache=True,
                                 config_kwargs=config, **options)
    require("gcsfs", "remote data", action="reading")
    if settings.anon:
        options["token"] = "anon"
    elif "token" not in options and not _credentials_configured("gcs"):
        options["token"] = "anon"
    options.setdefault("requests_timeout", settings.timeout)
    if options.get("token") == "anon" or options.get("endpoint_url") or os.environ.get(
            "STORAGE_EMULATOR_HOST"):
        # gcsfs's default class asks a gRPC control API for each bucket's layout (zonal or
        # hierarchical) before reads, and asks again after every failure: anonymous clients
        # are refused it and emulators do not serve it (against one, every read waited for that
        # call's 60 s time-out). The JSON API of the core class reads every other bucket.
        from gcsfs.core import GCSFileSystem

        return GCSFileSystem(asynchronous=True, skip_instance_cache=True, **options)
    return fsspec.filesystem("gcs", asynchronous=True, skip_instance_cache=True, **options)


@dataclass
class Remote:
    """One remote location (a store's root or a file) and how to fetch from it.

    Parameters
    ----------
    url : str
        Checked by :func:`check_url`.
    storage_options : dict, optional
        Passed to the fsspec filesystem (``anon``, ``key``/``secret``, ``endpoint_url``,
        ``token``, ``headers``, ...).
    settings : RemoteSettings, optional
        Default: :meth:`RemoteSettings.from_env`.
    """

    url: str
    storage_options: dict[str, Any] | None = None
    settings: RemoteSettings = field(default_factory=RemoteSettings.from_env)

    def __post_init__(self) -> None:
        self.url = check_url(self.url)
        self.scheme = urlsplit(self.url).scheme
        self.protocol = SCHEMES[self.scheme]
        self.host = (urlsplit(self.url).hostname or "").lower()
        self.fs = _filesystem(self.protocol, self.settings, self.storage_options)
        self.cache = _disk_cache(self.settings)
        self._sizes: OrderedDict[str, int | None] = OrderedDict()
        self._sizes_lock = threading.Lock()
        #: Suffix requests in flight and how many wait for each (see :meth:`_shared_tail`).
        self._tails: dict[tuple[str, int], list[Any]] = {}
        #: Whether the server answers suffix ranges (None: not asked yet).
        self.suffix_ranges: bool | None = None if self.protocol in ("http", "https") else False
        #: Requests made (attempts) and retried, for benchmarks and tests.
        self.requests = 0
        self.retried = 0

    # ------------------------------------------------------------------ naming
    def url_of(self, key: str | None) -> str:
        """The URL of ``key`` (``None``: the location itself), checked to stay inside."""
        if not key:
            return self.url
        return self.url + "/" + _check_key(key, self.url)

    def _target(self, url: str) -> str:
        """What the filesystem is asked for: the quoted URL (HTTP) or ``bucket/key``."""
        if self.protocol in ("http", "https"):
            parts = urlsplit(url)
            return urlunsplit((parts.scheme, parts.netloc, quote(unquote(parts.path), safe="/"),
                               "", ""))
        parts = urlsplit(url)
        return parts.netloc + unquote(parts.path)

    # ------------------------------------------------------------------ one request
    async def _once(self, url: str, start: int | None, stop: int | None, cap: int) -> bytes:
        if self.protocol in ("http", "https"):
            return await self._http_once(url, start, stop, cap)
        return await self._object_once(url, start, stop, cap)

    async def _http_once(self, url: str, start: int | None, stop: int | None, cap: int,
                         method: str = "GET", tail: int | None = None) -> Any:
        """One attempt. ``tail``: ask for the file's last ``tail`` bytes with one suffix range
        and return ``(size, bytes)``, the size from the answer's ``Content-Range``
        (:class:`_NoSuffix` if the server does not answer so)."""
        session = await self.fs.set_session()
        kw = dict(self.fs.kwargs)
        headers = dict(kw.pop("headers", None) or {})
        for drop in ("allow_redirects", "timeout"):
            kw.pop(drop, None)
        if method == "GET" and tail is not None:
            headers["Range"] = f"bytes=-{tail}"
        elif method == "GET":
            # A whole file is asked for with a range one byte beyond its cap: a file larger
            # than it can be is recognised without reading it whole.
            first, last = (0, cap) if start is None else (start, stop - 1)  # type: ignore[operator]
            if start is None or stop > start:  # type: ignore[operator]
                headers["Range"] = f"bytes={first}-{last}"
        target = self._target(url)
        for _ in range(_MAX_REDIRECTS + 1):
            async with session.request(method, target, headers=headers, allow_redirects=False,
                                       **kw) as r:
                status = r.status
                if status in (301, 302, 303, 307, 308):
                    target = self._redirect(url, target, r.headers.get("Location"))
                    continue
                if status in (404, 410):
                    raise _Missing()
                if status in (401, 403):
                    raise ReadError(f"{redact(url)}: access denied (HTTP {status}); check the "
                                    "credentials or whether the data is public")
                if status == 416:
                    if tail is not None:
                        raise _NoSuffix()
                    return b""
                if status == 429 or status >= 500:
                    raise _Transient(f"HTTP {status}")
                if status not in (200, 206):
                    raise ReadError(f"{redact(url)}: unexpected HTTP {status}")
                if method == "HEAD":
                    return r.content_length
                if tail is not None:
                    return await self._tail_body(url, r, tail)
                ranged = status == 206
                # A server that ignores Range sends the whole file: then the file's own bound
                # applies (a range inside a file is at most `cap` beyond its end).
                limit = cap if (start is None or not ranged) else stop - start  # type: ignore
                data = await self._body(url, r, limit)
                if start is not None and not ranged:
                    data = data[start:stop]
                return data
        raise ReadError(f"{redact(url)}: more than {_MAX_REDIRECTS} redirects")

    async def _body(self, url: str, r: Any, limit: int) -> bytes:
        """The body of answer ``r``, refused (unread if announced) beyond ``limit`` bytes."""
        length = r.content_length
        if length is not None and length > limit:
            raise ReadError(f"{redact(url)}: the server sends {length} bytes, more than "
                            f"the {limit} this request can take; refused unread")
        body = bytearray()
        while True:
            more = await r.content.read(min(1 << 20, limit + 1 - len(body)))
            if not more:
                break
            body += more
            if len(body) > limit:
                raise ReadError(f"{redact(url)}: the server sends more than the {limit} "
                                "bytes this request can take; refused")
        if length is not None and len(body) != length:
            raise _Transient(f"the body ended after {len(body)} of {length} bytes")
        return bytes(body)

    async def _tail_body(self, url: str, r: Any, tail: int) -> tuple[int, bytes]:
        """``(size, bytes)`` of the answer ``r`` to a suffix range of ``tail`` bytes: a 206
        whose ``Content-Range`` gives the file's size and a range ending at its end, of the
        bytes received. Anything else (a 200 with the whole file, no size) raises
        :class:`_NoSuffix`, its body unread."""
        match = _CONTENT_RANGE.match(r.headers.get("Content-Range", "").strip())
        if r.status != 206 or match is None:
            raise _NoSuffix()
        first, last, size = (int(v) for v in match.groups())
        if last != size - 1 or first != max(0, size - tail):
            raise _NoSuffix()
        data = await self._body(url, r, tail)
        if len(data) != last - first + 1:
            raise _Transient(f"{len(data)} bytes received for a range of {last - first + 1}")
        return size, data

    def _redirect(self, url: str, current: str, location: str | None) -> str:
        if not location:
            raise ReadError(f"{redact(url)}: a redirect without a Location")
        target = urljoin(current, location)
        parts = urlsplit(target)
        host = (parts.hostname or "").lower()
        if parts.scheme not in ("http", "https"):
            raise ReadError(f"{redact(url)}: redirected to a {parts.scheme or 'relative'}: URL; "
                            "refused")
        if host != self.host and host not in self.settings.redirect_hosts:
            raise ReadError(f"{redact(url)}: redirected to another host ({host}); refused "
                            f"(allow it with {ENV_REDIRECT_HOSTS}={host})")
        return target

    async def _object_once(self, url: str, start: int | None, stop: int | None,
                           cap: int) -> bytes:
        path = self._target(url)
        try:
            if start is None:
                data = await self.fs._cat_file(path, start=0, end=cap + 1)
            else:
                data = await self.fs._cat_file(path, start=start, end=stop)
        except FileNotFoundError:
            raise _Missing() from None
        except PermissionError:
            raise ReadError(f"{redact(url)}: access denied; check the credentials or whether "
                            "the data is public") from None
        except OSError as exc:
            text = str(exc)
            if "not satisfiable" in text or "InvalidRange" in text:
                return b""
            raise _Transient(limits.shorten(text, 120)) from None
        except Exception as exc:
            name = type(exc).__name__
            if name in ("NoCredentialsError", "PartialCredentialsError"):
                raise ReadError(f"{redact(url)}: no credentials found ({name}); pass --anon "
                                "for public data") from None
            if name in ("ClientError",) and "403" in str(exc):
                raise ReadError(f"{redact(url)}: access denied") from None
            raise _Transient(f"{name}: {limits.shorten(str(exc), 120)}") from None
        if start is None and len(data) > cap:
            raise ReadError(f"{redact(url)}: holds more than the {cap} bytes it can take; "
                            "refused")
        return bytes(data)

    async def _retrying(self, what: Any, url: str) -> Any:
        """``await what()`` with time-out, retries and back-off, within the deadline."""
        settings = self.settings
        deadline = time.monotonic() + settings.deadline
        delay = settings.backoff
        attempt = 0
        while True:
            attempt += 1
            self.requests += 1
            left = deadline - time.monotonic()
            try:
                async with asyncio.timeout(min(settings.timeout * 4, max(left, 0.001))):
                    return await what()
            except (_Missing, _NoSuffix, ReadError):
                raise
            except TimeoutError:
                reason = f"timed out after {min(settings.timeout * 4, max(left, 0.001)):.3g} s"
            except _Transient as exc:
                reason = str(exc)
            except (ConnectionError, OSError) as exc:
                reason = f"{type(exc).__name__}: {limits.shorten(str(exc) or '', 100)}"
            except Exception as exc:  # aiohttp.ClientError and the like: the connection failed
                if type(exc).__module__.split(".")[0] not in ("aiohttp", "botocore",
                                                              "aiobotocore", "gcsfs"):
                    raise
                reason = f"{type(exc).__name__}: {limits.shorten(str(exc) or '', 100)}"
            pause = delay * (1 + random.random())
            if attempt > settings.retries or time.monotonic() + pause >= deadline:
                tries = f" ({attempt} attempts)" if attempt > 1 else ""
                raise ReadError(f"{redact(url)}: {reason}{tries}")
            self.retried += 1
            await asyncio.sleep(pause)
            delay *= 2

    def _ident(self, key: str | None, start: int | None, stop: int | None, cap: int) -> str:
        """What the disk cache files a request's bytes under."""
        return f"{self.url_of(key)}\0{start}\0{stop}\0{cap}"

    async def _fetch(self, key: str | None, start: int | None, stop: int | None, cap: int,
                     cache: bool) -> bytes | None:
        url = self.url_of(key)
        ident = self._ident(key, start, stop, cap)
        if cache and self.cache is not None:
            kept = await asyncio.to_thread(self.cache.get, ident)
            if kept is not None:
                return kept
        try:
            data = await self._retrying(lambda: self._once(url, start, stop, cap), url)
        except _Missing:
            return None
        if cache and self.cache is not None:
            await asyncio.to_thread(self.cache.put, ident, data)
        return data

    # ------------------------------------------------------------------ public
    def fetch_many(self, requests: Sequence[tuple[str | None, int | None, int | None, int]],
                   *, cache: bool = True) -> list[bytes | None]:
        """Fetch ``(key, start, stop, cap)`` requests, many in flight at once.

        ``start`` ``None`` asks for the whole file, refused if larger than ``cap``; a range
        ``[start, stop)`` must come back whole. ``None`` in the result: the key does not exist.

        Inside :func:`.cancel.cancellable`, cancelling the token cancels every request in
        flight (their connections are closed) and raises :class:`.cancel.ReadCancelled`.

        Raises
        ------
        ReadError
            The first failure (naming its URL); the other requests are cancelled.
        """
        if not requests:
            return []
        token = cancel.current()
        if token is not None:
            token.check()

        async def run() -> list[bytes | None]:
            gate = asyncio.Semaphore(self.settings.concurrency)

            async def one(req: tuple[str | None, int | None, int | None, int]
                          ) -> bytes | None:
                async with gate:
                    return await self._fetch(*req, cache=cache)

            return await _gather(token, [one(r) for r in requests])

        return _zarr_loop_sync(run())

    def fetch_ranges(self, requests: Sequence[tuple[str | None, int | None, int | None, int]]
                     ) -> list[bytes | None]:
        """:meth:`fetch_many` with the byte ranges of each file merged into few requests.

        The ranges asked of one file are merged by :func:`coalesce` (with the settings'
        ``coalesce_gap`` and ``coalesce_bytes``); each merged request is capped at its own
        length and must come back whole, as a single range's request must, and its bytes are
        then cut into the ranges asked. Requests for whole files are made as they are. Requests
        to different files (and the merged requests of one) are all in flight at once. With the
        disk cache, each range is looked up and kept on its own, as :meth:`fetch_many` does.

        Returns
        -------
        list of bytes or None
            For each request, its bytes (a range shorter than asked if the file's answer was:
            the caller checks lengths), ``None`` if the file does not exist.
        """
        out: list[bytes | None] = [None] * len(requests)
        todo: list[int] = []
        for i, (key, start, stop, cap) in enumerate(requests):
            kept = (self.cache.get(self._ident(key, start, stop, cap))
                    if self.cache is not None else None)
            if kept is not None:
                out[i] = kept
            else:
                todo.append(i)
        # The ranges of each file, merged; whole files asked as they are.
        asked: list[tuple[str | None, int | None, int | None, int]] = []
        parts: list[list[tuple[int, int]]] = []  # per request asked: (request, offset in it)
        by_file: dict[str | None, list[int]] = {}
        for i in todo:
            key, start, _, _ = requests[i]
            if start is None:
                asked.append(requests[i])
                parts.append([(i, 0)])
            else:
                by_file.setdefault(key, []).append(i)
        settings = self.settings
        for key, members in by_file.items():
            spans, owner = coalesce([(requests[i][1], requests[i][2]) for i in members],
                                    settings.coalesce_gap, settings.coalesce_bytes)
            first = len(asked)
            for a, b in spans:
                asked.append((key, a, b, b - a))
                parts.append([])
            for i, span in zip(members, owner, strict=True):
                parts[first + span].append((i, requests[i][1] - spans[span][0]))  # type: ignore
        total = sum(r[3] if r[1] is None else r[2] - r[1] for r in asked)  # type: ignore
        limits.check_memory(total, f"{len(todo)} chunks fetched at once", self.url, ReadError)
        fetched = self.fetch_many(asked, cache=False)
        for j, cut in enumerate(parts):
            data, fetched[j] = fetched[j], None  # a merged answer is dropped once cut up
            for i, at in cut:
                key, start, stop, cap = requests[i]
                if data is None:
                    continue
                answer = data if start is None else data[at:at + stop - start]  # type: ignore
                out[i] = answer
                whole = start is None or len(answer) == stop - start  # type: ignore[operator]
                if self.cache is not None and whole:
                    self.cache.put(self._ident(key, start, stop, cap), answer)
        return out

    def fetch(self, key: str | None, start: int | None = None, stop: int | None = None, *,
              cap: int, cache: bool = True) -> bytes | None:
        """One request (see :meth:`fetch_many`)."""
        return self.fetch_many([(key, start, stop, cap)], cache=cache)[0]

    def fetch_tails(self, keys: Sequence[str], n: int) -> dict[str, bytes | None]:
        """The last ``n`` bytes of each file, with its size, one request each (HTTP only).

        Each file is asked for with a suffix range (``Range: bytes=-n``), whose answer gives
        the file's size in its ``Content-Range``: a shard's index and size in one round trip,
        where a HEAD and a range took two. The sizes are remembered as :meth:`sizes` does (a
        missing file as ``None``). A file shorter than ``n`` bytes comes whole. Where the server
        does not answer suffix ranges so (416, the whole file, no size), nothing more is asked
        that way of this location and the files not answered are left out: the caller asks
        their sizes and ranges as before. The disk cache is not used (what it keeps is filed
        by byte offsets, which need the size).

        Returns
        -------
        dict
            For each file answered, its last bytes (``None``: the file does not exist).
        """
        todo = list(dict.fromkeys(keys))
        if not todo or self.suffix_ranges is False:
            return {}
        token = cancel.current()
        if token is not None:
            token.check()
        no = object()

        async def run() -> list[Any]:
            gate = asyncio.Semaphore(self.settings.concurrency)

            async def one(key: str) -> Any:
                async with gate:
                    if self.suffix_ranges is False:
                        return no
                    try:
                        return await self._shared_tail(key, n)
                    except _Missing:
                        return None
                    except _NoSuffix:
                        self.suffix_ranges = False
                        return no

            return await _gather(token, [one(k) for k in todo])

        answers = _zarr_loop_sync(run())
        out: dict[str, bytes | None] = {}
        with self._sizes_lock:
            for key, found in zip(todo, answers, strict=True):
                if found is no:
                    continue
                if found is None:
                    self._sizes[key] = None
                    out[key] = None
                else:
                    self._sizes[key], out[key] = found
                    self.suffix_ranges = True
            while len(self._sizes) > 65536:
                self._sizes.popitem(last=False)
        return out

    async def _shared_tail(self, key: str, n: int) -> tuple[int, bytes]:
        """The suffix request of ``key``, shared by every read asking for it at once (the
        loader's reads in flight often want the same shard's index): one request, awaited by
        each; cancelled when every read waiting for it is (on the event loop only)."""
        ident = (key, n)
        shared = self._tails.get(ident)
        if shared is None:
            url = self.url_of(key)
            task = asyncio.ensure_future(self._retrying(
                lambda: self._http_once(url, None, None, n, tail=n), url))
            shared = self._tails[ident] = [task, 0]
            task.add_done_callback(lambda _: self._tails.pop(ident, None))
        task = shared[0]
        shared[1] += 1
        try:
            return await asyncio.shield(task)
        finally:
            shared[1] -= 1
            if not shared[1] and not task.done():
                task.cancel()  # no read wants it any more

    def knows_size(self, key: str | None) -> bool:
        """Whether the size of ``key`` is remembered (no request needed)."""
        with self._sizes_lock:
            return key in self._sizes

    def sizes(self, keys: Sequence[str | None]) -> list[int | None]:
        """Sizes in bytes of ``keys`` (``None``: missing), asked concurrently and remembered
        (a store is taken not to change while it is open)."""
        with self._sizes_lock:
            todo = [k for k in dict.fromkeys(keys) if k not in self._sizes]
        if todo:
            async def run() -> list[int | None]:
                gate = asyncio.Semaphore(self.settings.concurrency)

                async def one(key: str | None) -> int | None:
                    url = self.url_of(key)
                    async with gate:
                        try:
                            return await self._retrying(lambda: self._size_once(url), url)
                        except _Missing:
                            return None

                return await _gather(token, [one(k) for k in todo])

            token = cancel.current()
            if token is not None:
                token.check()
            found = _zarr_loop_sync(run())
            with self._sizes_lock:
                for key, size in zip(todo, found, strict=True):
                    self._sizes[key] = size
                while len(self._sizes) > 65536:
                    self._sizes.popitem(last=False)
        with self._sizes_lock:
            return [self._sizes.get(k) for k in keys]

    async def _size_once(self, url: str) -> int | None:
        if self.protocol in ("http", "https"):
            size = await self._http_once(url, None, None, 0, method="HEAD")
            if size is None:
                raise ReadError(f"{redact(url)}: the server does not give the file's size")
            return int(size)
        try:
            info = await self.fs._info(self._target(url))
        except FileNotFoundError:
            raise _Missing() from None
        except PermissionError:
            raise ReadError(f"{redact(url)}: access denied") from None
        size = info.get("size")
        if size is None or info.get("type") == "directory":
            raise _Missing()
        return int(size)


# --------------------------------------------------------------------------- chunk source
class RemoteSource:
    """The byte source :class:`~.zarr_chunks.ChunkReader` reads a remote store's chunks from.

    :meth:`prefetch` fetches the requests of a batch of chunks concurrently into a memo of the
    calling thread (the byte ranges of one shard merged into few requests,
    :meth:`Remote.fetch_ranges`); :meth:`read` and :meth:`whole` then serve them, and
    :meth:`forget` drops them after the batch is decoded (peak memory: one batch of encoded
    chunks).
    """

    #: Chunks (or shards) per batch of concurrent requests.
    batch = 256

    def __init__(self, remote: Remote) -> None:
        self.remote = remote
        self._local = threading.local()
        #: A store whose every chunk was written (splinecast's): a missing one is damage.
        self.strict = False

    def _found(self, key: str, data: Any) -> Any:
        if data is None and self.strict:
            raise ReadError(f"{self.path(key)}: not found (HTTP 404 or no such object), in a "
                            "store whose every chunk was written")
        return data

    def _memo(self) -> dict[tuple[str, int | None, int | None], bytes | None]:
        memo = getattr(self._local, "memo", None)
        if memo is None:
            memo = self._local.memo = {}
        return memo

    def path(self, key: str) -> str:
        return redact(self.remote.url_of(key))

    def stamp(self, key: str) -> tuple[int, int]:
        # A remote store is taken not to change while open: shard indexes are cached.
        return (0, 0)

    def size(self, key: str) -> int | None:
        return self._found(key, self.remote.sizes([key])[0])

    def prefetch_sizes(self, keys: Sequence[str]) -> None:
        self.remote.sizes(keys)

    def prefetch_tails(self, keys: Sequence[str], n: int) -> None:
        """Fetch the last ``n`` bytes of the files ``keys`` (shard indexes) and their sizes with
        one request each (:meth:`Remote.fetch_tails`), into the memo as the ranges
        ``[size - n, size)`` :meth:`read` is then asked for; what the server does not answer so
        is left for :meth:`prefetch_sizes` and :meth:`prefetch`."""
        memo = self._memo()
        todo = [key for key in keys if not self.remote.knows_size(key)]
        for key, data in self.remote.fetch_tails(todo, n).items():
            size = self.remote.sizes([key])[0]
            if data is not None and size is not None and size >= n and len(data) == n:
                memo[(key, size - n, size)] = data

    def prefetch(self, requests: Sequence[tuple[str, int | None, int | None, int]]) -> None:
        memo = self._memo()
        todo = [r for r in dict.fromkeys(requests) if (r[0], r[1], r[2]) not in memo]
        for req, data in zip(todo, self.remote.fetch_ranges(todo), strict=True):
            memo[(req[0], req[1], req[2])] = data

    def forget(self) -> None:
        self._memo().clear()

    def whole(self, key: str, cap: int) -> bytes | None:
        """The whole file ``key`` (``None`` if missing), refused if larger than ``cap``."""
        memo = self._memo()
        if (key, None, None) in memo:
            return self._found(key, memo[(key, None, None)])
        return self._found(key, self.remote.fetch(key, cap=cap))

    def read(self, key: str, start: int, stop: int) -> bytes:
        memo = self._memo()
        data = memo.get((key, start, stop))
        if data is None:
            whole = memo.get((key, None, None))
            if whole is not None:
                data = whole[start:stop]
            else:
                data = self.remote.fetch(key, start, stop, cap=stop - start)
        if data is None or len(data) != stop - start:
            got = "nothing" if data is None else f"{len(data)} bytes"
            raise ReadError(f"{self.path(key)}: bytes {start}..{stop} asked, {got} received "
                            "(the file is shorter than its index or listing says)")
        return data


# --------------------------------------------------------------------------- zarr store
_STORE_CLASS: list[type] = []


def _guarded_store_class() -> type:
    """zarr's ``FsspecStore`` with every read made by :class:`Remote` (checked keys, capped and
    validated metadata, retries); read-only."""
    from zarr.storage import FsspecStore

    class GuardedFsspecStore(FsspecStore):
        remote: Remote

        async def get(self, key: str, prototype: Any = None, byte_range: Any = None) -> Any:
            from zarr.abc.store import OffsetByteRequest, RangeByteRequest, SuffixByteRequest
            from zarr.core.buffer.core import default_buffer_prototype

            prototype = prototype or default_buffer_prototype()
            remote = self.remote
            url = remote.url_of(key)
            name = key.rsplit("/", 1)[-1]
            if name in _METADATA:
                if byte_range is not None:
                    raise ReadError(f"{redact(url)}: partial read of a metadata file")
                data = await remote._fetch(key, None, None, limits.MAX_JSON_BYTES, cache=False)
                if data is None:
                    return None
                if len(data) > limits.MAX_JSON_BYTES:
                    raise ReadError(f"{redact(url)}: metadata larger than "
                                    f"{limits.MAX_JSON_BYTES} bytes")
                limits.parse_json(data, redact(url))
                return prototype.buffer.from_bytes(data)
            # Chunks are read by zarr_chunks (bounded decoding); zarr itself reads chunk bytes
            # only for what it decodes on its own (never on splinecast's paths), capped here.
            cap = limits.memory_limit()[0]
            if isinstance(byte_range, RangeByteRequest):
                data = await remote._fetch(key, byte_range.start, byte_range.end,
                                           byte_range.end - byte_range.start, cache=True)
            elif isinstance(byte_range, OffsetByteRequest | SuffixByteRequest):
                raise ReadError(f"{redact(url)}: open-ended byte ranges are not read remotely")
            else:
                data = await remote._fetch(key, None, None, cap, cache=True)
            return None if data is None else prototype.buffer.from_bytes(data)

        async def get_partial_values(self, prototype: Any, key_ranges: Any) -> list[Any]:
            return list(await asyncio.gather(*(self.get(k, prototype, r)
                                               for k, r in key_ranges)))

        async def exists(self, key: str) -> bool:
            return (await self.get(key)) is not None

        def chunk_source(self) -> RemoteSource:
            """Where :mod:`.zarr_chunks` reads this store's chunks from."""
            return RemoteSource(self.remote)

    return GuardedFsspecStore


def open_remote_group(remote: Remote) -> Any:
    """Open the Zarr hierarchy (group or array) at ``remote`` read-only with zarr-python."""
    import zarr

    if not _STORE_CLASS:
        _STORE_CLASS.append(_guarded_store_class())
    path = remote._target(remote.url)
    store = _STORE_CLASS[0](fs=remote.fs, path=path, read_only=True)
    store.remote = remote
    return zarr.open(store=store, mode="r")


def has_zarr_metadata(remote: Remote) -> bool:
    """Whether ``remote`` holds a Zarr group or array (one of its metadata files exists)."""
    found = remote.fetch_many([(m, None, None, limits.MAX_JSON_BYTES)
                               for m in ("zarr.json", ".zgroup", ".zarray", ".zattrs")],
                              cache=False)
    return any(data is not None for data in found)


def basename(url: str) -> str:
    """The last name of the URL's path, unquoted (``head.nii.gz``)."""
    return _basename(url)


@contextlib.contextmanager
def download(remote: Remote, name: str) -> Any:
    """Download the file at ``remote`` into a private temporary folder, as ``name`` (made
    safe); yields its local path as text and removes the folder afterwards.

    The size is asked first and checked against the memory guard; blocks of the file are
    fetched several at a time, each capped at its own length.
    """
    url = redact(remote.url)
    size = remote.sizes([None])[0]
    if size is None:
        raise ReadError(f"{url}: not found (HTTP 404 or no such object)")
    limits.check_memory(size, "the file", url, ReadError)
    blocks = [(None, a, min(a + _FILE_BLOCK, size), min(_FILE_BLOCK, size - a))
              for a in range(0, size, _FILE_BLOCK)]
    folder = tempfile.mkdtemp(prefix="splinecast-remote-")
    safe = re.sub(r"[^A-Za-z0-9._-]", "_", name)[:200].lstrip(".") or "data"
    local = os.path.join(folder, safe)
    try:
        with open(local, "wb") as fh:
            for at in range(0, len(blocks), 16):
                parts = remote.fetch_many(blocks[at:at + 16], cache=False)
                for block, data in zip(blocks[at:at + 16], parts, strict=True):
                    if data is None or len(data) != block[2] - block[1]:
                        raise ReadError(f"{url}: changed or shrank while read")
                    fh.write(data)
        yield local
    except ReadError as exc:
        raise ReadError(str(exc).replace(local, url).replace(folder, url)) from None
    finally:
        # The readers memory-map or copy the data: a mapping outlives the file's name.
        shutil.rmtree(folder, ignore_errors=True)
