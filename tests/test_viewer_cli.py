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
