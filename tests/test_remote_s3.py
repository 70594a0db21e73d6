"""Reading from a real S3 endpoint: moto's standalone server on 127.0.0.1 (started here, in a
thread, on a free port), holding a pyramid written by ``splinecast pyramid`` and an image written
by ome-zarr-py. Renders equal the local render of the same store bit for bit.

Google Cloud Storage is tested the same way against its emulator (tests/test_remote_gcs.py).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

import splinecast as sc
from splinecast.errors import ReadError

pytest.importorskip("s3fs", reason="remote reading needs the remote extra")
pytest.importorskip("moto.server", reason="the S3 tests need moto[server] (the test extra)")
from remote_servers import S3Server  # noqa: E402
from remote_servers import render_complete as _render  # noqa: E402

BUCKET = "volumes"
SIZE = (32, 32)


@pytest.fixture(scope="module")
def s3(tmp_path_factory):
    """The endpoint, the local stores, and the bucket holding copies of them."""
    root = tmp_path_factory.mktemp("s3")
    vol = sc.demo("sphere", size=40)
    vol = sc.Volume(vol.data.astype(np.float32), spacing=vol.spacing, origin=vol.origin)
    done = subprocess.run([sys.executable, "-m", "splinecast.cli", "pyramid", "demo:sphere?size=40",
                           "-o", str(root / "cli.zarr"), "--brick", "8", "--quiet"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    stores = ["cli.zarr"]
    try:
        from ome_zarr.writer import write_image
    except ImportError:  # (ome-zarr is in the test extra; a machine without it skips its case)
        pass
    else:
        import zarr

        group = zarr.open_group(str(root / "omezarr.zarr"), mode="w")
        data = np.ascontiguousarray(vol.data.transpose(2, 1, 0))  # z, y, x
        write_image(data, group, axes="zyx", scale_factors=[2])
        stores.append("omezarr.zarr")
    server = S3Server().start()
    client = server.client()
    client.create_bucket(Bucket=BUCKET)
    # A public bucket, as open data is published: anonymous reads allowed (moto checks HEAD
    # requests against "s3:HeadObject", AWS against s3:GetObject: both are listed).
    client.put_bucket_policy(Bucket=BUCKET, Policy=json.dumps({
        "Version": "2012-10-17",
        "Statement": [{"Effect": "Allow", "Principal": "*",
                       "Action": ["s3:GetObject", "s3:ListBucket", "s3:HeadObject"],
                       "Resource": [f"arn:aws:s3:::{BUCKET}", f"arn:aws:s3:::{BUCKET}/*"]}]}))
    for name in stores:
        server.upload(BUCKET, root / name, name)
    sc.write(vol, root / "sphere.nrrd")
    client.put_object(Bucket=BUCKET, Key="files/sphere.nrrd",
                      Body=(root / "sphere.nrrd").read_bytes())
    yield server, root, stores
    server.stop()


def _options(server: S3Server) -> dict:
    return {"endpoint_url": server.endpoint, "key": "testing", "secret": "testing"}


@pytest.mark.parametrize("name", ["cli.zarr", "omezarr.zarr"])
def test_render_over_s3_equals_local(s3, name):
    server, root, stores = s3
    if name not in stores:
        pytest.skip("ome-zarr-py is not installed (it is in the test extra)")
    local = sc.read(root / name)
    remote = sc.read(f"s3://{BUCKET}/{name}", storage_options=_options(server))
    assert remote.metadata["source"] == f"s3://{BUCKET}/{name}"
    assert [lv.shape for lv in remote.levels] == [lv.shape for lv in local.levels]
    a, b = _render(remote), _render(local)
    assert np.array_equal(a.rgba, b.rgba)
    assert np.array_equal(a.depth, b.depth, equal_nan=True)


def test_cli_over_s3_anonymous(s3, tmp_path):
    from PIL import Image

    server, root, _ = s3
    env = {**os.environ, "AWS_ENDPOINT_URL_S3": server.endpoint}
    for var in ("AWS_ACCESS_KEY_ID", "AWS_SECRET_ACCESS_KEY", "AWS_PROFILE"):
        env.pop(var, None)
    out_remote, out_local = tmp_path / "remote.png", tmp_path / "local.png"
    common = ["--size", "32x32", "--iso", "0", "--quiet"]
    run = [sys.executable, "-m", "splinecast.cli"]
    done = subprocess.run([*run, "render", f"s3://{BUCKET}/cli.zarr", "--anon", "-o",
                           str(out_remote), *common], capture_output=True, text=True, env=env,
                          timeout=600)
    assert done.returncode == 0, done.stderr
    done = subprocess.run([*run, "render", str(root / "cli.zarr"), "-o", str(out_local),
                           *common], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert np.array_equal(np.asarray(Image.open(out_remote)), np.asarray(Image.open(out_local)))
    missing = subprocess.run([*run, "info", f"s3://{BUCKET}/absent.zarr", "--anon"],
                             capture_output=True, text=True, env=env, timeout=600)
    assert missing.returncode == 2
    lines = missing.stderr.strip().splitlines()
    assert len(lines) == 1 and f"s3://{BUCKET}/absent.zarr" in lines[0]


def test_single_file_over_s3(s3):
    server, root, _ = s3
    local = sc.read(root / "sphere.nrrd")
    remote = sc.read(f"s3://{BUCKET}/files/sphere.nrrd", storage_options=_options(server))
    assert np.array_equal(remote.data, local.data)
    with pytest.raises(ReadError, match="not found"):
        sc.read(f"s3://{BUCKET}/files/absent.nrrd", storage_options=_options(server))
