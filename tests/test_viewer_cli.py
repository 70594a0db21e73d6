"""`splinecast view` as a user starts it (a subprocess, stopped with Ctrl-C) and `sc.view` from
Python (the handle a notebook displays)."""

from __future__ import annotations

import html
import os
import signal
import subprocess
import sys
import urllib.error
import urllib.request

import pytest

import splinecast as sc
from splinecast.cli import main


def fetch(url: str) -> tuple[int, bytes]:
    try:
        with urllib.request.urlopen(url, timeout=60) as response:
            return response.status, response.read()
    except urllib.error.HTTPError as exc:
        return exc.code, b""


def test_view_prints_its_url_first_serves_it_and_stops_on_sigint():
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "splinecast.cli", "view", "demo:sphere?size=12", "--no-browser"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        url = proc.stdout.readline().strip()
        assert url.startswith("http://127.0.0.1:") and "/?token=" in url, url
        status, body = fetch(url)
        assert status == 200 and b"splinecast" in body
        assert fetch(url.split("?")[0])[0] == 401
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    assert out == ""  # the URL was the only line on stdout
    assert "Traceback" not in err


def test_view_host_warns_and_listens_where_asked():
    """``--host 0.0.0.0``: one warning line on stderr saying other machines can reach the
    viewer, the URL (first on stdout) names this machine and the port it was given (the
    kernel's choice, port 0), and the process listens on that address and port."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "splinecast.cli", "view", "demo:sphere?size=12", "--no-browser",
         "--host", "0.0.0.0", "--quiet"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        url = proc.stdout.readline().strip()
        port = int(url.split(":")[2].split("/")[0])
        assert url.startswith("http://127.0.0.1:") and port > 0, url
        assert ("0.0.0.0", port) in _listening(proc.pid)
        status, _ = fetch(url)
        assert status == 200
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    warnings = [line for line in err.splitlines() if "warning" in line]
    assert warnings == ["splinecast: warning: the viewer listens on 0.0.0.0: other machines can "
                        "reach it, and its token is the only protection"], err


def _listening(pid: int) -> set[tuple[str, int]]:
    """IPv4 TCP sockets in LISTEN state that process ``pid`` holds, from ``/proc`` (the kernel's
    view of the bound address, independent of the server's own report)."""
    inodes = set()
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.add(target[8:-1])
    found = set()
    with open(f"/proc/{pid}/net/tcp") as fh:
        next(fh)
        for line in fh:
            fields = line.split()
            local, state, inode = fields[1], fields[3], fields[9]
            if state == "0A" and inode in inodes:  # 0A: LISTEN
                address, port = local.split(":")
                octets = [str(int(address[i:i + 2], 16)) for i in (6, 4, 2, 0)]
                found.add((".".join(octets), int(port, 16)))
    return found


def test_view_on_this_machine_only_by_default_without_a_warning(caplog):
    """The default host is loopback: no warning, and the socket the kernel holds is
    127.0.0.1 at the port the URL names (``getsockname`` of the bound socket)."""
    import asyncio

    from splinecast.viewer.server import ViewerServer

    async def check():
        async with ViewerServer(sc.demo("sphere", size=8)) as server:
            port = int(server.url.split(":")[2].split("/")[0])
            return port, server.port, _listening(os.getpid())

    with caplog.at_level("WARNING", logger="splinecast.viewer"):
        port, reported, listening = asyncio.run(check())
    assert port == reported > 0 and ("127.0.0.1", port) in listening
    assert not [r for r in caplog.records if "listens on" in r.getMessage()]


@pytest.mark.parametrize(("args", "words"), [
    (["missing-file.nii.gz"], "missing-file.nii.gz"),
    (["demo:sphere?size=8", "--model", "cubic"], "--model must be one of"),
    (["demo:sphere?size=8", "--iso", "7"], "outside the data range"),
    (["demo:sphere?size=8", "--iso", "a"], "--iso must be comma-separated numbers"),
    (["demo:sphere?size=8", "--port", "70000"], "port must be an integer in 0..65535"),
    (["demo:sphere?size=8", "--host", "256.1.1.1"], "cannot listen on 256.1.1.1"),
])
def test_view_mistakes_are_one_line_and_status_2(args, words, capsys):
    code = main(["view", *args, "--no-browser"])
    out, err = capsys.readouterr()
    assert code == 2
    assert out == ""
    assert err.count("\n") == 1 and words in err, err


def test_sc_view_handle_serves_and_embeds_in_a_notebook():
    vol = sc.demo("sphere", size=12)
    handle = sc.view(vol, open_browser=False)
    try:
        assert handle.running
        assert handle.url.startswith("http://127.0.0.1:")
        status, body = fetch(handle.url)
        assert status == 200 and b"<canvas" in body
        inline = handle._repr_html_()
        assert f'<iframe src="{html.escape(handle.url, quote=True)}"' in inline
        assert handle.server.volume is vol
    finally:
        handle.stop()
    assert not handle.running
    with pytest.raises(urllib.error.URLError):
        urllib.request.urlopen(handle.url, timeout=10)
    handle.stop()  # idempotent


def test_sc_view_refuses_bad_arguments_before_starting():
    with pytest.raises(sc.ParameterError, match="mode must be one of"):
        sc.view(sc.demo("sphere", size=8), mode="xray", open_browser=False)


def test_import_splinecast_does_not_import_the_server_library():
    code = ("import sys, splinecast as sc; assert 'aiohttp' not in sys.modules; "
            "assert 'splinecast.viewer' not in sys.modules; sc.view; "
            "assert 'aiohttp' not in sys.modules; print('ok')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.stdout.strip() == "ok", out.stderr
