"""Reading over HTTP from a real aiohttp server on 127.0.0.1 (tests/remote_servers.py), with
injected latency and faults: renders equal the local store's bit for bit; failures give one line
naming the URL.

Every render here is 32x32, trilinear, iso, float32 data: one kernel compilation for the file.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import splinecast as sc
from splinecast.errors import ReadError

pytest.importorskip("fsspec", reason="remote reading needs the remote extra")
from remote_servers import Faults, FileServer  # noqa: E402
from remote_servers import render_complete as _render  # noqa: E402

ISO = 0.0
SIZE = (32, 32)


@pytest.fixture(scope="module")
def stores(tmp_path_factory) -> Path:
    """A folder of stores: splinecast's pyramid (Zarr v3, sharded), the same unsharded, a
    bioformats2raw collection holding the first, and single files of the same volume."""
    root = tmp_path_factory.mktemp("served")
    vol = sc.demo("sphere", size=40)
    vol = sc.Volume(vol.data.astype(np.float32), spacing=vol.spacing, origin=vol.origin)
    sc.build_pyramid(vol, root / "sphere.zarr", brick=8, shard=16, progress=False)
    mv = sc.read(root / "sphere.zarr")
    _write_ngff(root / "plain.zarr", mv, zarr_format=3)  # OME-Zarr 0.5, not sharded
    _write_ngff(root / "v2.zarr", mv, zarr_format=2)  # OME-Zarr 0.4
    b2r = root / "collection.zarr"
    b2r.mkdir()
    (b2r / "zarr.json").write_text(json.dumps({
        "zarr_format": 3, "node_type": "group",
        "attributes": {"ome": {"version": "0.5", "bioformats2raw.layout": 3}}}))
    shutil.copytree(root / "sphere.zarr", b2r / "0")
    sc.write(vol, root / "sphere.nrrd")
    sc.write(vol, root / "sphere.npy")
    return root


def _write_ngff(path: Path, mv, zarr_format: int) -> None:
    """The levels of ``mv`` as an unsharded OME-Zarr image (0.4 on Zarr v2, 0.5 on v3) in
    8^3 chunks, written with zarr-python and NGFF metadata by hand (axes z, y, x)."""
    import zarr

    group = zarr.open_group(path, mode="w", zarr_format=zarr_format)
    datasets = []
    for i, level in enumerate(mv.levels):
        data = level.read((0, 0, 0), level.shape).transpose(2, 1, 0)
        group.create_array(str(i), data=np.ascontiguousarray(data), chunks=(8, 8, 8))
        datasets.append({"path": str(i), "coordinateTransformations": [
            {"type": "scale", "scale": list(level.spacing[::-1])},
            {"type": "translation", "translation": list(level.origin[::-1])}]})
    multiscales = [{"axes": [{"name": a, "type": "space"} for a in "zyx"],
                    "datasets": datasets, "name": path.name}]
    if zarr_format == 2:
        multiscales[0]["version"] = "0.4"
        group.attrs.update({"multiscales": multiscales})
    else:
        group.attrs.update({"ome": {"version": "0.5", "multiscales": multiscales}})


@pytest.fixture
def server(stores):
    with FileServer(stores, Faults()) as srv:
        yield srv


def _same(a: sc.Frame, b: sc.Frame) -> None:
    assert np.array_equal(a.rgba, b.rgba)
    assert np.array_equal(a.depth, b.depth, equal_nan=True)


@pytest.mark.parametrize("name", ["sphere.zarr", "plain.zarr", "v2.zarr", "collection.zarr"])
def test_render_over_http_equals_local(stores, name):
    local = _render(sc.read(stores / name))
    with FileServer(stores, Faults(latency=0.01)) as srv:
        remote = sc.read(f"{srv.url}/{name}")
        assert remote.metadata["source"].startswith(f"{srv.url}/{name}")
        frame = _render(remote)
        gets = [entry for entry in srv.faults.log if entry[0] == "GET"]
    _same(frame, local)
    assert frame.stats["complete"]
    # Chunks are fetched with a range (whole chunk capped: bytes=0-<cap>, or a shard's part).
    metadata = ("zarr.json", ".zarray", ".zattrs", ".zgroup")
    chunks = [r for _, path, r in gets if not path.endswith(metadata)]
    assert chunks and all(r.startswith("bytes=") for r in chunks)


def test_levels_equal_local_and_requests_overlap(stores):
    """Many requests are in flight at once: with 50 ms per request, reading a level of 125
    chunks takes far less than 125 x 50 ms (timing is not asserted; the overlap is seen in the
    server's count of concurrent requests instead)."""
    local = sc.read(stores / "plain.zarr")
    faults = Faults(latency=0.05)
    with FileServer(stores, faults) as srv:
        remote = sc.read(f"{srv.url}/plain.zarr")
        for a, b in zip(remote.levels, local.levels, strict=True):
            assert np.array_equal(a.read((0, 0, 0), a.shape), b.read((0, 0, 0), b.shape))
    assert faults.peak >= 8


@pytest.mark.parametrize("kind", [500, 503, "reset", "short"])
def test_transient_faults_are_retried(stores, kind):
    local = sc.read(stores / "sphere.zarr").levels[0]
    with FileServer(stores, Faults()) as srv:
        remote = sc.read(f"{srv.url}/sphere.zarr").levels[0]
        srv.faults.add("/0/c/", kind, count=2)
        data = remote.read((0, 0, 0), remote.shape)
        assert srv.faults.rules["/0/c/"][1] == 0  # the faults were met, and passed
    assert np.array_equal(data, local.read((0, 0, 0), local.shape))


def test_slow_body_times_out_then_retries(stores, monkeypatch):
    monkeypatch.setenv("SPLINECAST_REMOTE_TIMEOUT", "0.3")
    local = sc.read(stores / "plain.zarr").levels[1]
    with FileServer(stores, Faults(slow_seconds=2)) as srv:
        remote = sc.read(f"{srv.url}/plain.zarr").levels[1]
        srv.faults.add("/1/c/", "slow", count=1)
        data = remote.read((0, 0, 0), remote.shape)
    assert np.array_equal(data, local.read((0, 0, 0), local.shape))


def test_deadline_gives_one_line(stores, monkeypatch):
    monkeypatch.setenv("SPLINECAST_REMOTE_TIMEOUT", "0.2")
    monkeypatch.setenv("SPLINECAST_REMOTE_DEADLINE", "1.5")
    with FileServer(stores, Faults(slow_seconds=2)) as srv:
        remote = sc.read(f"{srv.url}/plain.zarr").levels[1]
        srv.faults.add("/1/c/", "slow", count=1000)
        with pytest.raises(ReadError) as err:
            remote.read((0, 0, 0), remote.shape)
    text = str(err.value)
    assert f"{srv.url}/plain.zarr/1/c/" in text and "timed out" in text
    assert "\n" not in text


@pytest.mark.parametrize("status", [401, 403, 404])
def test_denied_or_missing_chunk_names_the_url(server, status):
    remote = sc.read(f"{server.url}/sphere.zarr").levels[0]
    server.faults.add("/0/c/0/0/0", status, count=1000)
    with pytest.raises(ReadError) as err:
        remote.read((0, 0, 0), remote.shape)
    text = str(err.value)
    assert f"{server.url}/sphere.zarr/0/c/0/0/0" in text and "\n" not in text
    assert ("denied" if status != 404 else "not found") in text


def test_oversized_response_is_refused_unread(server):
    remote = sc.read(f"{server.url}/plain.zarr").levels[0]
    server.faults.big_bytes = 256 << 20
    server.faults.add("/0/c/0/0/0", "big", count=1)
    with pytest.raises(ReadError, match="refused unread"):
        remote.read((0, 0, 0), (8, 8, 8))


def test_redirects_stay_on_the_host(server):
    here = f"{server.url}/sphere.zarr/zarr.json"
    server.faults.add("/moved.zarr/zarr.json", f"redirect:{here}", count=1)
    # (the same host: followed; the store's other keys then 404 under /moved.zarr)
    with pytest.raises(ReadError):
        sc.read(f"{server.url}/moved.zarr").levels[0].read((0, 0, 0), (1, 1, 1))
    elsewhere = here.replace("127.0.0.1", "localhost")
    server.faults.add("/away.zarr/zarr.json", f"redirect:{elsewhere}", count=10)
    with pytest.raises(ReadError, match="redirected to another host"):
        sc.read(f"{server.url}/away.zarr")


def test_metadata_path_leaving_the_store_is_refused(stores, tmp_path):
    bad = tmp_path / "bad.zarr"
    shutil.copytree(stores / "plain.zarr", bad)
    meta = json.loads((bad / "zarr.json").read_text())
    meta["attributes"]["ome"]["multiscales"][0]["datasets"][0]["path"] = "../plain.zarr/0"
    (bad / "zarr.json").write_text(json.dumps(meta))
    with FileServer(tmp_path, Faults()) as srv, pytest.raises(ReadError) as err:
        sc.read(f"{srv.url}/bad.zarr")
    assert "'..'" in str(err.value) or "leaves the store" in str(err.value)
    assert not any("plain.zarr" in path for _, path, _ in srv.faults.log)


@pytest.mark.parametrize("key", ["../x", "a/../../x", "/etc/passwd", "file:///etc/passwd",
                                 "a\\b", "a//b", "a/\x00"])
def test_store_keys_stay_inside(server, key):
    from splinecast.io.remote import Remote

    remote = Remote(f"{server.url}/sphere.zarr")
    with pytest.raises(ReadError, match="leaves the store"):
        remote.url_of(key)


@pytest.mark.parametrize("url, words", [
    ("ftp://example.org/x.zarr", "unknown URL scheme"),
    ("file:///etc/passwd", "file:// URLs are not read"),
    ("http:///x.zarr", "no host"),
    ("https://example.org:99999/x.zarr", "malformed URL"),
    ("s3://user:secret@bucket/x.zarr", "credentials inside the URL"),
    ("http://example.org/a b.zarr", "malformed URL"),
])
def test_bad_urls_are_refused(url, words):
    with pytest.raises(ReadError) as err:
        sc.read(url)
    assert words in str(err.value)
    assert "secret" not in str(err.value)


def test_single_files_over_http(server, stores):
    for name in ("sphere.nrrd", "sphere.npy"):
        local = sc.read(stores / name)
        remote = sc.read(f"{server.url}/{name}")
        assert np.array_equal(remote.data, local.data)
        assert remote.spacing == local.spacing and remote.origin == local.origin
        assert remote.metadata["source"] == f"{server.url}/{name}"
    with pytest.raises(ReadError, match="not found"):
        sc.read(f"{server.url}/absent.nrrd")


def _cli(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    import os

    full = {**os.environ, **(env or {})}
    return subprocess.run([sys.executable, "-m", "splinecast.cli", *args], capture_output=True,
                          text=True, env=full, timeout=600)


def test_cli_render_over_http_equals_local_and_uses_the_disk_cache(stores, tmp_path):
    from PIL import Image

    local_png, remote_png = tmp_path / "local.png", tmp_path / "remote.png"
    cache = tmp_path / "cache"
    common = ["--size", "32x32", "--iso", "0", "--quiet"]
    assert _cli("render", str(stores / "sphere.zarr"), "-o", str(local_png), *common
                ).returncode == 0
    with FileServer(stores, Faults(latency=0.01)) as srv:
        url = f"{srv.url}/sphere.zarr"
        done = _cli("render", url, "-o", str(remote_png), "--cache-dir", str(cache), *common)
        assert done.returncode == 0, done.stderr
        first = len(srv.faults.log)
        again = _cli("render", url, "-o", str(remote_png), "--cache-dir", str(cache),
                     "--cache-size", "64MiB", *common)
        assert again.returncode == 0, again.stderr
        second = len(srv.faults.log) - first
        info = _cli("info", url)
    assert np.array_equal(np.asarray(Image.open(remote_png)), np.asarray(Image.open(local_png)))
    assert any(cache.rglob("*")) and second < first  # chunks came from the cache
    assert info.returncode == 0 and url in info.stdout


def test_cli_bad_store_gives_one_line_exit_2_nothing_written(stores, tmp_path):
    lying = tmp_path / "lying.zarr"
    shutil.copytree(stores / "plain.zarr", lying)
    for level in lying.glob("[0-9]"):
        meta = json.loads((level / "zarr.json").read_text())
        meta["chunk_grid"]["configuration"]["chunk_shape"] = [4, 4, 4]  # they hold 8^3
        (level / "zarr.json").write_text(json.dumps(meta))
    out = tmp_path / "out.png"
    with FileServer(tmp_path, Faults()) as srv:
        cases = [(f"{srv.url}/lying.zarr", f"{srv.url}/lying.zarr/"),
                 (f"{srv.url}/none.zarr", "no Zarr group"),
                 ("gopher://x/y.zarr", "unknown URL scheme")]
        for url, words in cases:
            done = _cli("render", url, "-o", str(out), "--size", "32x32", "--iso", "0")
            lines = done.stderr.strip().splitlines()
            assert done.returncode == 2, done.stderr
            assert len(lines) == 1 and words in lines[0], lines
            assert not out.exists()


def test_cli_movie_over_http_equals_the_local_movie(stores, tmp_path):
    """`splinecast movie URL` writes the frames `splinecast movie PATH` writes."""
    common = ["--size", "32x32", "--iso", "0", "--frames", "3", "--quiet"]
    local, remote = tmp_path / "local", tmp_path / "remote"
    assert _cli("movie", str(stores / "sphere.nrrd"), "-o", f"{local}/", *common).returncode == 0
    with FileServer(stores, Faults()) as srv:
        done = _cli("movie", f"{srv.url}/sphere.nrrd", "-o", f"{remote}/", *common)
    assert done.returncode == 0, done.stderr
    names = sorted(p.name for p in local.iterdir())
    assert len(names) == 3 and names == sorted(p.name for p in remote.iterdir())
    for name in names:
        assert (local / name).read_bytes() == (remote / name).read_bytes(), name


def test_cancelling_the_token_stops_the_requests_in_flight(server, stores):
    """A fetch inside ``cancellable(token)`` whose request the server holds: cancelling the
    token from another thread closes the connection (the server sees its client leave) and the
    fetch raises ReadCancelled; the filesystem serves the next fetch."""
    import threading

    from splinecast.io.cancel import CancelToken, ReadCancelled, cancellable
    from splinecast.io.remote import Remote

    remote = Remote(f"{server.url}/sphere.zarr")
    key = "0/c/0/0/0"
    server.faults.hold = f"/sphere.zarr/{key}"
    token = CancelToken()
    outcome: list[str] = []

    def fetch() -> None:
        with cancellable(token):
            try:
                remote.fetch(key, cap=1 << 20, cache=False)
                outcome.append("answered")
            except ReadCancelled:
                outcome.append("cancelled")

    thread = threading.Thread(target=fetch)
    thread.start()
    assert server.faults.held.wait(timeout=60)
    token.cancel()
    assert server.faults.dropped.wait(timeout=60)
    thread.join(timeout=60)
    assert outcome == ["cancelled"]
    server.release()
    data = remote.fetch(key, cap=1 << 20, cache=False)
    assert data == (stores / "sphere.zarr" / key).read_bytes()


@pytest.fixture(scope="module")
def pyramid(tmp_path_factory) -> Path:
    """A four-level pyramid (64^3 float32 sphere, bricks of 8, shards of 16)."""
    root = tmp_path_factory.mktemp("pyramid")
    vol = sc.demo("sphere", size=64)
    vol = sc.Volume(vol.data.astype(np.float32), spacing=vol.spacing, origin=vol.origin)
    sc.build_pyramid(vol, root / "sphere.zarr", brick=8, shard=16, progress=False)
    return root


def test_camera_move_cancels_the_reads_under_way(pyramid):
    """A close-up of a corner wants level 0 there; the server holds every level-0 request
    unanswered. Moving to the whole view (levels 1 and 2) stops the read under way: the server
    sees the held request's connection closed, and the new view completes while level 0 is
    still held (without the cancellation the loader waits on the held request and the new
    view never gets its bricks). The new view equals the local store's render of it."""
    options = dict(budget="64MiB", whole_level=False)
    local = sc.read(pyramid / "sphere.zarr")
    lo, hi = (np.asarray(b, float) for b in local.bounds)
    corner = sc.Camera.orbit(local, azimuth=30, elevation=20, size=SIZE,
                             fit=(lo, lo + (hi - lo) / 4))
    whole = sc.Camera.orbit(local, azimuth=30, elevation=20, size=SIZE)
    with sc.Scene(local, **options) as scene:
        expected = scene.render(whole, iso=ISO, complete=True)
    assert 0 not in expected.stats["cut_levels"]  # the whole view needs no level-0 brick

    faults = Faults()
    with FileServer(pyramid, faults) as srv:
        scene = sc.Scene(sc.read(f"{srv.url}/sphere.zarr"), **options)
        try:
            faults.hold = "/sphere.zarr/0/"
            first = scene.render(corner, iso=ISO, wait=False)
            assert first.stats["cut_levels"] == {0: first.stats["cut_bricks"]}
            assert faults.held.wait(timeout=120), "the close-up's level-0 read never started"
            frame = scene.render(whole, iso=ISO, complete=True)
            assert faults.dropped.wait(timeout=60), "the held request was not cancelled"
            cancelled = scene.stream.cache.stats()["reads_cancelled"]
        finally:
            srv.release()
            scene.close()
    _same(frame, expected)
    assert frame.stats["complete"] and cancelled >= 1
    assert all("/sphere.zarr/0/" in entry for entry in faults.dropped_log)


# --------------------------------------------------------------------------- merged range requests
def test_coalesce_spans_hold_every_range_and_are_maximal():
    """Random byte ranges: each lies whole in the span it is given; a span is no longer than
    the cap unless it is one range; two neighbouring spans could not have been joined (gap or
    cap); cap 0 leaves every range its own span."""
    from splinecast.io.remote import coalesce

    rng = np.random.default_rng(7)
    for _ in range(200):
        n = int(rng.integers(1, 40))
        starts = rng.integers(0, 5000, n)
        ranges = [(int(a), int(a + rng.integers(1, 400))) for a in starts]
        gap, cap = int(rng.integers(0, 300)), int(rng.integers(1, 3000))
        spans, owner = coalesce(ranges, gap, cap)
        for (a, b), k in zip(ranges, owner, strict=True):
            assert spans[k][0] <= a and b <= spans[k][1]
        members = [[r for r, k in zip(ranges, owner, strict=True) if k == j]
                   for j in range(len(spans))]
        for (a, b), inside in zip(spans, members, strict=True):
            assert inside and a == min(r[0] for r in inside) and b == max(r[1] for r in inside)
            assert b - a <= cap or len(inside) == 1
        for (a0, b0), (a1, b1) in zip(spans, spans[1:], strict=False):
            assert a0 <= a1
            assert a1 - b0 > gap or max(b0, b1) - a0 > cap
        alone, owner0 = coalesce(ranges, gap, 0)
        assert sorted(alone) == sorted(ranges) and len(set(owner0)) == len(ranges)


def _shard_index(path: Path, count: int) -> np.ndarray:
    """(offset, length) of each inner chunk of a shard file, read by the test itself: the
    index at the end of the file (16 bytes per chunk, then a 4-byte crc32c)."""
    raw = path.read_bytes()[-(16 * count + 4):-4]
    index = np.frombuffer(raw, dtype="<u8").reshape(-1, 2)
    return index[index[:, 0] != np.iinfo(np.uint64).max]


def _data_gets(log, name: str) -> dict[str, list[str]]:
    """The server's GETs of a store's chunk files (not metadata), by path: their ranges."""
    out: dict[str, list[str]] = {}
    for method, path, header in log:
        if method == "GET" and f"/{name}/" in path and not path.endswith(("zarr.json",
                                                                           ".zattrs")):
            out.setdefault(path, []).append(header)
    return out


def test_level_read_asks_each_shard_once_for_its_chunks(stores, monkeypatch):
    """Reading a whole sharded level: the server sees, per shard, no HEAD, one suffix range for
    its index (which gives its size too) and one range for all its inner chunks (the bytes from
    its first chunk to the end of its last, taken from the index by the test); with merging
    off, one range per inner chunk. Both read what the local store holds."""
    name = "sphere.zarr"
    local = sc.read(stores / name).levels[0]
    expected = local.read((0, 0, 0), local.shape)
    count = 8  # inner chunks per shard: (16 / 8)^3
    seen = {}
    for merge in ("8MiB", "0"):
        monkeypatch.setenv("SPLINECAST_REMOTE_COALESCE_BYTES", merge)
        faults = Faults()
        with FileServer(stores, faults) as srv:
            level = sc.read(f"{srv.url}/{name}").levels[0]
            assert np.array_equal(level.read((0, 0, 0), level.shape), expected)
            assert level.reader.source.remote.requests == len(faults.log)  # the reader's count
        assert not [entry for entry in faults.log if entry[0] == "HEAD"]
        seen[merge] = _data_gets(faults.log, f"{name}/0")
    shards = sorted(stores.glob(f"{name}/0/c/*/*/*"))
    assert len(shards) == 27 and set(seen["8MiB"]) == set(seen["0"])
    for shard in shards:
        path = "/" + shard.relative_to(stores).as_posix()
        index = _shard_index(shard, count)
        first, last = int(index[:, 0].min()), int((index[:, 0] + index[:, 1]).max())
        tail = f"bytes=-{16 * count + 4}"  # the index with its size: one suffix range
        merged, alone = seen["8MiB"][path], seen["0"][path]
        assert sorted(merged) == sorted([tail, f"bytes={first}-{last - 1}"]), path
        assert sorted(alone) == sorted([tail] + [f"bytes={int(o)}-{int(o + n) - 1}"
                                                 for o, n in index]), path


def test_render_over_http_merged_equals_local_with_fewer_requests(stores, monkeypatch):
    """The complete render of the sharded store over HTTP equals the local render bit for bit
    with and without merging; merging cuts the range requests the server sees, and the loader's
    ``remote_requests``, once it has nothing left to read, equals the server's count."""
    name = "sphere.zarr"
    local = _render(sc.read(stores / name))
    assert local.stats["remote_requests"] == 0
    ranged = {}
    for merge in ("8MiB", "0"):
        monkeypatch.setenv("SPLINECAST_REMOTE_COALESCE_BYTES", merge)
        faults = Faults(latency=0.01)
        counted: list[tuple[int, int]] = []

        def settled(scene, faults=faults, counted=counted):
            assert scene.stream.cache.settle(timeout=120)  # the read-ahead done too
            counted.append((scene.stream.cache.stats()["remote_requests"], len(faults.log)))

        with FileServer(stores, faults) as srv:
            frame = _render(sc.read(f"{srv.url}/{name}"), after=settled)
        _same(frame, local)
        assert frame.stats["complete"] and 0 < frame.stats["remote_requests"] <= len(faults.log)
        assert counted[0][0] == counted[0][1]
        ranged[merge] = sum(len(v) for v in _data_gets(faults.log, name).values())
    assert ranged["8MiB"] < ranged["0"]


def _read_with_fault(stores, kind, monkeypatch, merge: str) -> tuple[object, list]:
    """Read the whole level 0 of the sharded store once (sizes and shard indexes are then
    known), inject ``kind`` for the next request to the middle shard and read it again: the
    data read (or the error raised) and the server's log of that second read."""
    monkeypatch.setenv("SPLINECAST_REMOTE_COALESCE_BYTES", merge)
    monkeypatch.setenv("SPLINECAST_REMOTE_RETRIES", "2")
    faults = Faults()
    with FileServer(stores, faults) as srv:
        level = sc.read(f"{srv.url}/sphere.zarr").levels[0]
        level.read((0, 0, 0), level.shape)
        before = len(faults.log)
        faults.add("/sphere.zarr/0/c/1/1/1", kind, count=1 if kind in ("short", 503) else 99)
        try:
            outcome: object = level.read((0, 0, 0), level.shape)
        except ReadError as exc:
            outcome = str(exc).replace(srv.url, "URL")
        return outcome, faults.log[before:]


@pytest.mark.parametrize("kind", ["short", 503])
def test_merged_request_cut_short_is_retried(stores, kind, monkeypatch):
    """A merged request whose body is cut short (or that meets a server error) is retried as a
    single chunk's request is, and the level equals the local one."""
    local = sc.read(stores / "sphere.zarr").levels[0]
    data, log = _read_with_fault(stores, kind, monkeypatch, "8MiB")
    assert np.array_equal(data, local.read((0, 0, 0), local.shape))
    mine = [r for m, p, r in log if p.endswith("/0/c/1/1/1")]
    index = _shard_index(stores / "sphere.zarr/0/c/1/1/1", 8)
    span = f"bytes={int(index[:, 0].min())}-{int((index[:, 0] + index[:, 1]).max()) - 1}"
    assert mine == [span, span]  # the merged range, cut, then asked again


@pytest.mark.parametrize("kind", [403, 404, 500, "truncate"])
def test_merged_request_failure_gives_the_same_error(stores, kind, monkeypatch):
    """A merged request refused, missing, failing for good or answered with fewer bytes than
    asked: one line naming the shard's URL, the same as without merging (where the failing
    request is a single chunk's)."""
    merged, _ = _read_with_fault(stores, kind, monkeypatch, "8MiB")
    alone, _ = _read_with_fault(stores, kind, monkeypatch, "0")
    assert isinstance(merged, str) and isinstance(alone, str)
    assert "URL/sphere.zarr/0/c/1/1/1" in merged and "\n" not in merged
    if kind == "truncate":  # which chunk comes up short first depends on the requests
        words = "asked", "received (the file is shorter than its index or listing says)"
        assert all(w in merged and w in alone for w in words)
    else:
        assert merged == alone


@pytest.mark.parametrize("damage", ["past the data", "over its neighbour"])
def test_damaged_shard_index_gives_the_local_error_over_http(stores, tmp_path, damage):
    """A shard whose index points past its data, or gives an inner chunk the bytes of its
    neighbour too (two zstd frames: twice the chunk's size, refused before decompressing):
    read over HTTP with merged requests, the error is the one the same store gives on disk
    (one line naming the inner chunk), the store's location aside."""
    import google_crc32c

    store = tmp_path / "bad.zarr"
    shutil.copytree(stores / "sphere.zarr", store)
    shard = store / "0/c/1/1/1"
    raw = bytearray(shard.read_bytes())
    at = len(raw) - (16 * 8 + 4)
    index = np.frombuffer(bytes(raw[at:-4]), dtype="<u8").reshape(-1, 2).copy()
    first = int(np.argmin(index[:, 0]))
    if damage == "past the data":
        index[first, 0] = at + 1  # the index's own bytes are not the data's
    else:
        after = int(np.flatnonzero(index[:, 0] == index[first].sum())[0])
        index[first, 1] += index[after, 1]
    body = index.astype("<u8").tobytes()
    raw[at:] = body + google_crc32c.value(body).to_bytes(4, "little")
    shard.write_bytes(bytes(raw))

    def error(source) -> str:
        level = sc.read(source).levels[0]
        with pytest.raises(ReadError) as err:
            level.read((0, 0, 0), level.shape)
        return str(err.value)

    local = error(store)
    with FileServer(tmp_path, Faults()) as srv:
        remote = error(f"{srv.url}/bad.zarr")
        ranges = [r for m, p, r in srv.faults.log if p.endswith("/0/c/1/1/1") and m == "GET"]
    # The index is checked before any chunk is asked for; else its chunks are one request.
    assert len(ranges) == (1 if damage == "past the data" else 2)
    assert "\n" not in remote and "(1, 1, 1)" not in remote  # an inner chunk, not the shard
    assert remote.replace(f"{srv.url}/bad.zarr", "STORE") == local.replace(str(store), "STORE")
    words = "outside the shard's data" if damage == "past the data" else "declares"
    assert words in remote


def test_shard_indexes_are_fetched_once_per_level(tmp_path):
    """A level of 125 shards read twice through the same reader: the second read asks for no
    shard index and no size again (both kept, as a view read ring by ring needs), only the
    chunks; both equal the store read from disk."""
    vol = sc.demo("sphere", size=80)
    vol = sc.Volume(vol.data.astype(np.float32), spacing=vol.spacing, origin=vol.origin)
    sc.build_pyramid(vol, tmp_path / "many.zarr", brick=8, shard=16, progress=False)
    local = sc.read(tmp_path / "many.zarr").levels[0]
    expected = local.read((0, 0, 0), local.shape)
    shards = list(tmp_path.glob("many.zarr/0/c/*/*/*"))
    assert len(shards) == 125
    faults = Faults()
    with FileServer(tmp_path, faults) as srv:
        level = sc.read(f"{srv.url}/many.zarr").levels[0]
        assert np.array_equal(level.read((0, 0, 0), level.shape), expected)
        before = len(faults.log)
        assert np.array_equal(level.read((0, 0, 0), level.shape), expected)
        again = faults.log[before:]
    tail = 16 * 8 + 4  # the index: 8 entries and its checksum, at the end of each shard
    sizes = {"/" + p.relative_to(tmp_path).as_posix(): p.stat().st_size for p in shards}
    assert all(m == "GET" for m, _, _ in again) and len(again) == len(shards)
    for _, path, header in again:
        assert not header.endswith(f"-{sizes[path] - 1}"), (path, header)  # not the index
        assert int(header.rsplit("-", 1)[1]) < sizes[path] - tail


# --------------------------------------------------------------------------- reads in flight
@pytest.fixture(scope="module")
def one_shard(tmp_path_factory) -> Path:
    """A pyramid (64^3 float32 sphere, bricks of 8) whose level 0 is one shard file: a loader
    read of a batch of bricks asks that file one request at a time (its index with its size,
    then its chunks merged into one range), so requests to it at once are reads at once."""
    root = tmp_path_factory.mktemp("one")
    vol = sc.demo("sphere", size=64)
    vol = sc.Volume(vol.data.astype(np.float32), spacing=vol.spacing, origin=vol.origin)
    sc.build_pyramid(vol, root / "one.zarr", brick=8, shard=64, progress=False)
    assert len([p for p in (root / "one.zarr/0").rglob("*") if p.is_file()
                and p.name != "zarr.json"]) == 1
    return root


def _level0_bricks(source, faults=None, reads=None) -> tuple[dict, dict]:
    """Every level-0 brick of ``source`` read by a brick cache's loader (one request for them
    all, in C order: 64 batches of 8 siblings), and the cache's stats."""
    from splinecast.multires.store.cache import BrickCache

    with BrickCache(sc.read(source), "64MiB", reads=reads) as cache:
        counts = cache.octree.counts[0]
        keys = [(0, *map(int, idx)) for idx in np.indices(counts).reshape(3, -1).T]
        assert len(keys) == 512
        cache.request(keys)
        if faults is not None and faults.hold:
            assert faults.held.wait(timeout=60), "no read of level 0 started"
        assert cache.settle(timeout=120), "the loader did not finish (one read at a time?)"
        return {key: cache.get(key).data for key in keys}, cache.stats()


def test_loader_keeps_several_reads_in_flight(one_shard, monkeypatch):
    """The server holds the requests for level 0's chunks (not its index, which reads asking
    for it at once share) until two are held at once: the loader finishes only if it reads two
    batches at the same time (the server sees them, and so does the cache's ``reads_peak``).
    The reads that start together share one request for the shard's index (with 50 ms per
    request, the server never answers two at once). With ``reads=1`` the server never sees two
    requests at once (a control of the measure). Either way the bricks equal those read from
    the store on disk."""
    monkeypatch.setenv("SPLINECAST_REMOTE_COALESCE_GAP", "16MiB")  # one range per read
    expected, local = _level0_bricks(one_shard / "one.zarr")
    assert local["reads_peak"] == 1  # a store on disk: one read at a time
    watch = "/one.zarr/0/c/"  # the shard, not the metadata
    faults = Faults(latency=0.05, hold=watch, release_at=2, hold_suffix=False, watch=watch)
    with FileServer(one_shard, faults) as srv:
        got, stats = _level0_bricks(f"{srv.url}/one.zarr", faults)
    assert faults.watch_peak >= 2 and stats["reads_peak"] >= 2
    assert faults.suffix_peak == 1
    assert stats["reads_peak"] <= 8  # SPLINECAST_REMOTE_READS' default
    alone = Faults(latency=0.01, watch=watch)
    with FileServer(one_shard, alone) as srv:
        single, stats = _level0_bricks(f"{srv.url}/one.zarr", reads=1)
    assert alone.watch_peak == 1 and stats["reads_peak"] == 1
    for key, data in expected.items():
        assert np.array_equal(got[key], data) and np.array_equal(single[key], data), key


def test_bad_reads_setting_gives_one_line(one_shard, monkeypatch):
    monkeypatch.setenv("SPLINECAST_REMOTE_READS", "0")
    with FileServer(one_shard, Faults()) as srv, pytest.raises(ReadError) as err:
        sc.read(f"{srv.url}/one.zarr")
    assert "SPLINECAST_REMOTE_READS=0 must be within 1..256" in str(err.value)


# --------------------------------------------------------------------------- suffix ranges
@pytest.mark.parametrize("answer", [416, "whole"])
def test_shard_index_without_suffix_ranges(stores, answer):
    """A server that answers a suffix range with 416, or with the whole file (200): the reader
    then asks each shard's size (HEAD) and index (a range to the file's end), as before, and
    tries no more suffix ranges on that store; the levels equal the local ones."""
    name = "sphere.zarr"
    local = sc.read(stores / name)
    faults = Faults(no_suffix=answer)
    with FileServer(stores, faults) as srv:
        remote = sc.read(f"{srv.url}/{name}")
        logs = []
        for a, b in zip(remote.levels[:2], local.levels[:2], strict=True):
            before = len(faults.log)
            assert np.array_equal(a.read((0, 0, 0), a.shape), b.read((0, 0, 0), b.shape))
            logs.append(faults.log[before:])
    for n, log in enumerate(logs):
        shards = sorted(stores.glob(f"{name}/{n}/c/*/*/*"))
        sizes = {"/" + p.relative_to(stores).as_posix(): p.stat().st_size for p in shards}
        suffix = [path for _, path, r in log if r.startswith("bytes=-")]
        heads = sorted(path for method, path, _ in log if method == "HEAD")
        tails = sorted(path for method, path, r in log if path in sizes and method == "GET"
                       and r.endswith(f"-{sizes[path] - 1}"))
        assert heads == tails == sorted(sizes), n  # one HEAD and one index range per shard
        assert sorted(suffix) == (sorted(sizes) if n == 0 else []), n  # tried once only
