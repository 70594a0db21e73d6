"""Side by side: splinecast's default isosurface pictures and PyVista's, on the MRI and ML.

For each volume the same camera (position, focal point, up, 30 degree field of view, size)
renders

* ``splinecast``: ``Scene(volume).render(camera)``, the defaults (smooth normals, antialiased);
* ``splinecast-exact``: ``normals="exact", samples=1``, the defaults before smooth shading and
  antialiasing (the trilinear gradient, one ray per pixel);
* ``pyvista``: ``grid.contour([iso])`` shown as ``mesh.plot()`` shows it, PyVista's defaults
  (a flying-edges mesh, flat-shaded, coloured by the scalar, with a scalar bar and axes,
  multisampled), from splinecast's camera;
* ``pyvista-smooth``: the same with ``smooth_shading=True`` (vertex normals interpolated) and
  splinecast's surface colour, so the shading can be compared.

The pictures go to ``docs/_static/pyvista/`` as palette PNGs (small enough to commit);
``docs/accuracy.rst`` shows them. The time of each is printed (one render each: indicative
only). Needs pyvista and an offscreen OpenGL (``scripts/install_bench.sh``). Usage::

    python benchmarks/pyvista_gallery.py [--out DIR] [--size 400x300]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from PIL import Image

import splinecast as sc

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _machine import MRI  # noqa: E402

OUT = HERE.parent / "docs" / "_static" / "pyvista"


def volumes() -> list[tuple[str, sc.Volume, dict]]:
    """(name, volume, camera options) of the pictures: a close view of the MRI's cortex at its
    automatic isovalue, and Marschner-Lobb 128^3 at 0.5."""
    out = []
    if MRI.exists():
        out.append(("mri", sc.read(MRI), {"azimuth": 30.0, "elevation": 20.0, "zoom": 2.2}))
    else:
        print(f"note: {MRI} is missing, the MRI pictures are skipped", file=sys.stderr)
    ml = sc.demo("marschner-lobb", size=128)
    out.append(("ml", ml, {"azimuth": 30.0, "elevation": 30.0, "zoom": 1.25}))
    return out


def save(rgb: np.ndarray, path: Path) -> None:
    """An 8-bit RGB picture as a 256-colour PNG (a third of the bytes, no visible loss)."""
    Image.fromarray(np.ascontiguousarray(rgb[..., :3])).quantize(
        256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE).save(path, optimize=True)


def render_all(out: Path, size: tuple[int, int]) -> dict:
    import pyvista as pv

    out.mkdir(parents=True, exist_ok=True)
    times: dict = {}
    for name, vol, view in volumes():
        scene = sc.Scene(vol)
        iso = sc.auto_iso(vol) if name == "mri" else 0.5  # the demo's default isovalue
        cam = sc.Camera.orbit(scene, size=size, fit=sc.content_box(vol, iso=iso), **view)
        entry = times[name] = {"iso": float(iso), "shape": list(vol.shape)}
        for variant, options in (("splinecast", {}),
                                 ("splinecast-exact", {"normals": "exact", "samples": 1})):
            scene.render(cam, iso=iso, **options)  # compilation
            start = time.perf_counter()
            frame = scene.render(cam, iso=iso, **options)
            entry[variant] = {"ms": (time.perf_counter() - start) * 1e3,
                              "antialiased": frame.stats.get("antialiased", 0)}
            save(frame.to_uint8(), out / f"{name}-{variant}.png")
        grid = pv.ImageData(dimensions=vol.shape, spacing=vol.spacing, origin=vol.origin)
        grid.point_data["values"] = np.asarray(vol.data).ravel(order="F")
        start = time.perf_counter()
        mesh = grid.contour([iso])
        contour_ms = (time.perf_counter() - start) * 1e3
        front = sc.Shading().front_color
        for variant, options in (("pyvista", {}),
                                 ("pyvista-smooth", {"smooth_shading": True, "color": front})):
            start = time.perf_counter()
            plotter = pv.Plotter(off_screen=True, window_size=list(size))
            plotter.add_mesh(mesh, **options)  # what mesh.plot() shows, and its axes
            plotter.show_axes()
            # splinecast's camera exactly (plot(cpos=...) may refit the view to the mesh).
            plotter.camera.position = tuple(cam.position)
            plotter.camera.focal_point = tuple(cam.look_at)
            plotter.camera.up = tuple(cam.up)
            plotter.camera.view_angle = cam.fov
            plotter.reset_camera_clipping_range()
            image = plotter.screenshot(return_img=True)
            plotter.close()
            entry[variant] = {"contour_ms": contour_ms,
                              "plot_ms": (time.perf_counter() - start) * 1e3,
                              "triangles": int(mesh.n_cells)}
            save(np.asarray(image), out / f"{name}-{variant}.png")
        print(name, json.dumps(entry))
    return times


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(OUT), help="output folder")
    parser.add_argument("--size", default="400x300", help="picture WIDTHxHEIGHT")
    args = parser.parse_args(argv)
    render_all(Path(args.out), sc.camera.parse_size(args.size))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
