"""Reading from a real Google Cloud Storage endpoint: the pure-Python ``gcp-storage-emulator``
started here on 127.0.0.1 (in a thread, on a free port), holding a pyramid written by
``splinecast pyramid`` and a single file. ``gs://`` URLs are read through gcsfs, pointed at the
emulator by ``storage_options={"endpoint_url": ...}`` or by ``STORAGE_EMULATOR_HOST`` (the
variable Google's own clients honour); renders equal the local render of the same store bit for
bit.
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

import splinecast as sc
from splinecast.errors import ReadError

pytest.importorskip("gcsfs", reason="remote reading needs the remote extra")
pytest.importorskip("gcp_storage_emulator",
                    reason="the GCS tests need gcp-storage-emulator (the test extra)")
from remote_servers import GCSServer  # noqa: E402
from remote_servers import render_complete as _render  # noqa: E402

BUCKET = "volumes"
SIZE = (32, 32)


@pytest.fixture(scope="module")
def gcs(tmp_path_factory):
    """The emulator, and the local folder whose store and file it holds copies of."""
    root = tmp_path_factory.mktemp("gcs")
    done = subprocess.run([sys.executable, "-m", "splinecast.cli", "pyramid", "demo:sphere?size=40",
                           "-o", str(root / "x.zarr"), "--brick", "8", "--quiet"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    vol = sc.demo("sphere", size=24)
    (root / "files").mkdir()
    sc.write(sc.Volume(vol.data.astype(np.float32), spacing=vol.spacing, origin=vol.origin),
             root / "files" / "sphere.nrrd")
    server = GCSServer(BUCKET).start()
    try:
        server.upload(root / "x.zarr", "x.zarr")
        server.upload(root / "files", "files")
        yield server, root
    finally:
        server.stop()


def test_render_over_gcs_equals_local(gcs):
    server, root = gcs
    local = sc.read(root / "x.zarr")
    remote = sc.read(f"gs://{BUCKET}/x.zarr", storage_options={"endpoint_url": server.endpoint})
    assert remote.metadata["source"] == f"gs://{BUCKET}/x.zarr"
    assert [lv.shape for lv in remote.levels] == [lv.shape for lv in local.levels]
    for a, b in zip(remote.levels, local.levels, strict=True):
        assert np.array_equal(a.read((0, 0, 0), a.shape), b.read((0, 0, 0), b.shape))
    a, b = _render(remote), _render(local)
    assert a.stats["complete"]
    assert np.array_equal(a.rgba, b.rgba)
    assert np.array_equal(a.depth, b.depth, equal_nan=True)


def test_emulator_host_from_the_environment(gcs, monkeypatch):
    """``STORAGE_EMULATOR_HOST`` alone points gcsfs at the emulator (no storage_options); a
    single file is downloaded and read; a missing object is one line naming its URL."""
    server, root = gcs
    monkeypatch.setenv("STORAGE_EMULATOR_HOST", server.endpoint)
    local = sc.read(root / "files" / "sphere.nrrd")
    remote = sc.read(f"gs://{BUCKET}/files/sphere.nrrd")
    assert np.array_equal(remote.data, local.data)
    assert remote.spacing == local.spacing and remote.origin == local.origin
    with pytest.raises(ReadError) as err:
        sc.read(f"gs://{BUCKET}/files/absent.nrrd")
    assert f"gs://{BUCKET}/files/absent.nrrd" in str(err.value) and "\n" not in str(err.value)


def test_cli_render_over_gcs_equals_local(gcs, tmp_path):
    from PIL import Image

    server, root = gcs
    env = {**os.environ, "STORAGE_EMULATOR_HOST": server.endpoint}
    env.pop("GOOGLE_APPLICATION_CREDENTIALS", None)
    out_remote, out_local = tmp_path / "remote.png", tmp_path / "local.png"
    common = ["--size", "32x32", "--iso", "0", "--quiet"]
    run = [sys.executable, "-m", "splinecast.cli"]
    done = subprocess.run([*run, "render", f"gs://{BUCKET}/x.zarr", "--anon", "-o",
                           str(out_remote), *common], capture_output=True, text=True, env=env,
                          timeout=600)
    assert done.returncode == 0, done.stderr
    done = subprocess.run([*run, "render", str(root / "x.zarr"), "-o", str(out_local), *common],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert np.array_equal(np.asarray(Image.open(out_remote)), np.asarray(Image.open(out_local)))
    missing = subprocess.run([*run, "info", f"gs://{BUCKET}/absent.zarr", "--anon"],
                             capture_output=True, text=True, env=env, timeout=600)
    assert missing.returncode == 2
    lines = missing.stderr.strip().splitlines()
    assert len(lines) == 1 and f"gs://{BUCKET}/absent.zarr" in lines[0], lines
    assert not (tmp_path / "absent.png").exists()
