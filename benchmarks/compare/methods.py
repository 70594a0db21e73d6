"""The rendering methods under comparison, behind one small interface each.

Isosurface methods (:class:`IsoMethod`): ``new_iso(iso, cam)`` goes from a new isovalue to a
finished image in memory (the timed "first image"), ``frame(cam)`` renders the current surface
from another viewpoint (the timed steady frame), ``surface(cam)`` returns depth and normals for the
quality metrics (untimed).

Volume methods (:class:`VolumeMethod`, MIP and DVR): ``frame(cam)`` renders, ``image(cam)``
returns the image for the quality comparison.

VTK renders offscreen into an EGL or OSMesa context on Mesa's llvmpipe software rasterizer (no
display, no GPU). Every VTK timing ends with the pixels read back into memory, as splinecast's
images are, so both sides stop the clock on a finished image (llvmpipe may otherwise still be
rasterizing when ``Render()`` returns).
"""

from __future__ import annotations

import functools
import inspect
import json
import os
import subprocess
import sys
from typing import Any

import numpy as np

import splinecast as sc

from .metrics import mesh_normals_at, zbuffer_to_depth

# --------------------------------------------------------------------------- availability

#: Offscreen window classes tried in this order (both run on llvmpipe without a GPU).
WINDOW_CLASSES = ("vtkEGLRenderWindow", "vtkOSOpenGLRenderWindow")

_PROBE = """
import json, sys
import vtkmodules.vtkRenderingOpenGL2  # noqa: F401  (registers the OpenGL factories)
from vtkmodules.vtkRenderingCore import vtkRenderWindow, vtkRenderer
rw = vtkRenderWindow()
rw.SetOffScreenRendering(1)
rw.AddRenderer(vtkRenderer())
rw.SetSize(8, 8)
rw.Render()
caps = rw.ReportCapabilities() or ""
renderer = next((l.split(":", 1)[1].strip() for l in caps.splitlines()
                 if l.startswith("OpenGL renderer string")), "")
ok = bool(renderer) and rw.IsCurrent() is not None
print(json.dumps({"window": type(rw).__name__, "renderer": renderer, "ok": ok}))
"""


@functools.cache
def vtk_status() -> dict[str, Any]:
    """Whether VTK is importable and can render offscreen, probed in subprocesses.

    A failing OpenGL context can abort the process, so each window class is tried in a child.
    The first class that renders is exported in ``VTK_DEFAULT_OPENGL_WINDOW`` for this process
    and its children. Returns ``{"available": bool, "reason": str, "window": ..., "renderer": ...,
    "version": ...}``.
    """
    try:
        import vtkmodules  # noqa: F401
        from vtkmodules.vtkCommonCore import vtkVersion
    except ImportError as exc:
        return {"available": False,
                "reason": f"VTK not installed ({exc}); install the bench extra: "
                          "pip install -e '.[bench]' (make bench-deps)"}
    version = vtkVersion.GetVTKVersion()
    preset = os.environ.get("VTK_DEFAULT_OPENGL_WINDOW")
    errors = []
    for window in ([preset] if preset else list(WINDOW_CLASSES)):
        env = dict(os.environ, VTK_DEFAULT_OPENGL_WINDOW=window)
        try:
            run = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True,
                                 text=True, timeout=120)
        except subprocess.TimeoutExpired:
            errors.append(f"{window}: timed out")
            continue
        lines = [line for line in run.stdout.splitlines() if line.startswith("{")]
        if run.returncode == 0 and lines:
            info = json.loads(lines[-1])
            if info["ok"] and info["window"] == window:
                os.environ["VTK_DEFAULT_OPENGL_WINDOW"] = window
                return {"available": True, "reason": "", "window": window,
                        "renderer": info["renderer"], "version": version}
        tail = (run.stderr.strip().splitlines() or ["no output"])[-1]
        errors.append(f"{window}: exit {run.returncode}: {tail[-200:]}")
    return {"available": False, "version": version,
            "reason": "VTK cannot create an offscreen OpenGL context ("
                      + "; ".join(errors) + "); run scripts/install_bench.sh"}


@functools.cache
def skimage_status() -> dict[str, Any]:
    """Whether scikit-image is importable (its meshes are rendered with VTK, checked apart)."""
    try:
        import skimage
    except ImportError as exc:
        return {"available": False, "reason": f"scikit-image not installed ({exc}); "
                "install the bench extra: pip install -e '.[bench]'"}
    return {"available": True, "reason": "", "version": skimage.__version__}


def vtk_threads() -> dict[str, Any]:
    """VTK's SMP backend and thread count, and llvmpipe's rasterizer threads."""
    from vtkmodules.vtkCommonCore import vtkSMPTools

    return {
        "vtk_smp_backend": vtkSMPTools.GetBackend(),
        "vtk_smp_threads": vtkSMPTools.GetEstimatedNumberOfThreads(),
        # Mesa's llvmpipe uses LP_NUM_THREADS rasterizer threads, by default one per core.
        "llvmpipe_threads": int(os.environ.get("LP_NUM_THREADS", os.cpu_count() or 1)),
    }


def splinecast_threads() -> int:
    """Threads splinecast's Numba kernels run on."""
    import numba

    return int(numba.get_num_threads())


# --------------------------------------------------------------------------- VTK helpers

def vtk_image(volume: sc.Volume):
    """The volume as vtkImageData (same origin and spacing; x varies fastest, as in VTK)."""
    from vtkmodules.util import numpy_support
    from vtkmodules.vtkCommonDataModel import vtkImageData

    image = vtkImageData()
    image.SetDimensions(*volume.shape)
    image.SetSpacing(*volume.spacing)
    image.SetOrigin(*volume.origin)
    # data[i, j, k] has i along x; VTK wants x fastest, i.e. Fortran order of the same array.
    flat = np.asarray(volume.data).ravel(order="F")
    array = numpy_support.numpy_to_vtk(flat, deep=True)
    array.SetName("values")
    image.GetPointData().SetScalars(array)
    return image


def enable_vtk_threads() -> None:
    """Run VTK's SMP filters (flying edges) on all cores.

    The PyPI wheels start with the ``Sequential`` backend; ``STDThread`` ships in them too and is
    what a user would switch on. ``VTK_SMP_BACKEND_IN_USE`` set by the user wins.
    """
    from vtkmodules.vtkCommonCore import vtkSMPTools

    if not os.environ.get("VTK_SMP_BACKEND_IN_USE"):
        vtkSMPTools.SetBackend("STDThread")


class VtkWindow:
    """An offscreen render window with one renderer, driven by splinecast cameras."""

    def __init__(self, size: tuple[int, int]) -> None:
        import vtkmodules.vtkRenderingOpenGL2  # noqa: F401
        import vtkmodules.vtkRenderingVolumeOpenGL2  # noqa: F401
        from vtkmodules.vtkRenderingCore import vtkMapper, vtkRenderer, vtkRenderWindow

        vtk_status()  # selects the offscreen window class that works here (cached)
        enable_vtk_threads()
        # No polygon offset: it would push the mesh's depth away from its true position.
        vtkMapper.SetResolveCoincidentTopologyToOff()
        self.renderer = vtkRenderer()
        self.renderer.SetBackground(0.0, 0.0, 0.0)
        self.window = vtkRenderWindow()
        self.window.SetOffScreenRendering(1)
        self.window.SetMultiSamples(0)   # one sample per pixel centre, like the ray casters
        self.window.AddRenderer(self.renderer)
        self.window.SetSize(*size)
        self.size = size

    def set_camera(self, cam: sc.Camera) -> None:
        """Match splinecast's camera: eye, focal point, view up, vertical view angle."""
        if (cam.width, cam.height) != self.size:
            self.window.SetSize(cam.width, cam.height)
            self.size = (cam.width, cam.height)
        vc = self.renderer.GetActiveCamera()
        vc.SetPosition(*cam.position)
        vc.SetFocalPoint(*cam.look_at)
        vc.SetViewUp(*cam.up)
        vc.SetViewAngle(cam.fov)
        vc.SetParallelProjection(cam.ortho)
        if cam.ortho:
            vc.SetParallelScale(0.5 * cam.ortho_height)
        self.renderer.ResetCameraClippingRange()

    def render(self, cam: sc.Camera) -> np.ndarray:
        """Render and read the RGBA pixels back (row 0 on top); the timed unit of work."""
        from vtkmodules.util import numpy_support
        from vtkmodules.vtkCommonCore import vtkUnsignedCharArray

        self.set_camera(cam)
        self.window.Render()
        pixels = vtkUnsignedCharArray()
        w, h = self.size
        self.window.GetRGBACharPixelData(0, 0, w - 1, h - 1, 0, pixels)
        return np.flipud(numpy_support.vtk_to_numpy(pixels).reshape(h, w, 4))

    def depth(self, cam: sc.Camera) -> np.ndarray:
        """World depth along each pixel ray from the z-buffer of a render with ``cam``."""
        from vtkmodules.util import numpy_support
        from vtkmodules.vtkCommonCore import vtkFloatArray

        self.render(cam)
        w, h = self.size
        z = vtkFloatArray()
        self.window.GetZbufferData(0, 0, w - 1, h - 1, z)
        zb = np.flipud(numpy_support.vtk_to_numpy(z).reshape(h, w))
        near, far = self.renderer.GetActiveCamera().GetClippingRange()
        return zbuffer_to_depth(zb, cam, near, far)

    def close(self) -> None:
        self.window.Finalize()


# --------------------------------------------------------------------------- isosurfaces

class IsoMethod:
    """Base class of isosurface methods."""

    name = ""
    #: What "threads" means for this method, filled by :meth:`threads`.
    def __init__(self, volume: sc.Volume, size: tuple[int, int]) -> None:
        self.volume = volume
        self.size = size
        self.iso: float | None = None

    def new_iso(self, iso: float, cam: sc.Camera) -> None:
        raise NotImplementedError

    def frame(self, cam: sc.Camera) -> None:
        raise NotImplementedError

    def surface(self, cam: sc.Camera) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def threads(self) -> dict[str, Any]:
        raise NotImplementedError

    def info(self) -> dict[str, Any]:
        """Method-specific facts for the report (triangle count, ...)."""
        return {}

    def close(self) -> None:
        pass


class SplinecastIso(IsoMethod):
    """splinecast's exact isosurface (any model): block classification plus analytic ray casting.

    Timed images are the colour buffer alone (``outputs=("rgba",)``), like the meshes' RGBA read
    back from VTK, and without antialiasing (``samples=1``), like the meshes rasterized without
    multisampling; the quality metrics ask for depth and normals. ``normals`` is the render's
    (the default smooth shading field, or the model's own gradient).
    """

    name = "splinecast exact"

    def __init__(self, volume: sc.Volume, size: tuple[int, int], model: str = "trilinear",
                 normals: str = "smooth"):
        super().__init__(volume, size)
        self.scene = sc.Scene(volume, model=model)
        self.model = model
        self.normals = normals
        if model != "trilinear":
            self.name = f"splinecast exact ({model})"
        if normals != "smooth":
            self.name += f" ({normals} normals)"
        self._frame: sc.Frame | None = None

    def _render(self, cam: sc.Camera, outputs: tuple[str, ...]) -> sc.Frame:
        return self.scene.render(cam, iso=self.iso, outputs=outputs, normals=self.normals,
                                 samples=1)

    def new_iso(self, iso: float, cam: sc.Camera) -> None:
        self.scene.set_iso(iso)
        self.iso = iso
        self._frame = self._render(cam, COLOUR)

    def frame(self, cam: sc.Camera) -> None:
        self._frame = self._render(cam, COLOUR)

    def surface(self, cam: sc.Camera) -> tuple[np.ndarray, np.ndarray]:
        frame = self._render(cam, ("depth", "normal"))
        return frame.depth, frame.normal

    def threads(self) -> dict[str, Any]:
        return {"threads": splinecast_threads(), "what": "numba threads"}


#: What a timed splinecast frame fills: the image.
COLOUR = ("rgba",)


class _MeshIso(IsoMethod):
    """A triangle mesh extracted per isovalue and rasterized by VTK's OpenGL polydata mapper."""

    def __init__(self, volume: sc.Volume, size: tuple[int, int]) -> None:
        super().__init__(volume, size)
        from vtkmodules.vtkRenderingCore import vtkActor, vtkPolyDataMapper

        self.win = VtkWindow(size)
        self.mapper = vtkPolyDataMapper()
        self.mapper.ScalarVisibilityOff()
        self.actor = vtkActor()
        self.actor.SetMapper(self.mapper)
        self.actor.GetProperty().SetColor(0.9, 0.85, 0.75)
        self.win.renderer.AddActor(self.actor)

    def polydata(self):
        raise NotImplementedError

    def frame(self, cam: sc.Camera) -> None:
        self.win.render(cam)

    def surface(self, cam: sc.Camera) -> tuple[np.ndarray, np.ndarray]:
        from vtkmodules.util import numpy_support

        depth = self.win.depth(cam)
        normals = np.full(depth.shape + (3,), np.nan)
        hit = np.isfinite(depth)
        pd = self.polydata()
        if hit.any() and pd.GetNumberOfCells():
            origins, directions = cam.rays()
            points = origins[hit] + depth[hit][:, None] * directions[hit]
            verts = numpy_support.vtk_to_numpy(pd.GetPoints().GetData()).astype(np.float64)
            tris = _triangles(pd)
            vnorm = numpy_support.vtk_to_numpy(pd.GetPointData().GetNormals()).astype(np.float64)
            normals[hit] = mesh_normals_at(points, verts, tris, vnorm)
        return depth, normals

    def info(self) -> dict[str, Any]:
        pd = self.polydata()
        return {"triangles": int(pd.GetNumberOfCells()) if pd is not None else 0}

    def threads(self) -> dict[str, Any]:
        return vtk_threads()

    def close(self) -> None:
        self.win.close()


def _triangles(polydata) -> np.ndarray:
    """Triangle vertex indices (m, 3) of a polydata made only of triangles."""
    from vtkmodules.util import numpy_support

    polys = polydata.GetPolys()
    conn = numpy_support.vtk_to_numpy(polys.GetConnectivityArray())
    return conn.reshape(-1, 3).astype(np.int64)


class VtkContourIso(_MeshIso):
    """VTK's flying edges (multi-threaded, vtkSMPTools) or classic marching cubes, with normals
    from the interpolated gradient (``ComputeNormalsOn``)."""

    def __init__(self, volume: sc.Volume, size: tuple[int, int], algorithm: str) -> None:
        super().__init__(volume, size)
        if algorithm == "flying-edges":
            from vtkmodules.vtkFiltersCore import vtkFlyingEdges3D as Filter

            self.name = "VTK flying edges"
        else:
            from vtkmodules.vtkFiltersCore import vtkMarchingCubes as Filter

            self.name = "VTK marching cubes"
        self.image = vtk_image(volume)
        self.filter = Filter()
        self.filter.SetInputData(self.image)
        self.filter.ComputeNormalsOn()
        self.filter.ComputeScalarsOff()
        self.mapper.SetInputConnection(self.filter.GetOutputPort())

    def new_iso(self, iso: float, cam: sc.Camera) -> None:
        self.filter.SetValue(0, iso)
        self.filter.Update()
        self.win.render(cam)
        self.iso = iso

    def polydata(self):
        return self.filter.GetOutput()


class VtkSmoothedIso(VtkContourIso):
    """Flying edges, then the windowed-sinc smoothing a user applies against the staircase look
    (``vtkWindowedSincPolyDataFilter``, 20 iterations, pass band 0.1, feature edges off), normals
    recomputed from the smoothed triangles (``vtkPolyDataNormals``, no splitting)."""

    def __init__(self, volume: sc.Volume, size: tuple[int, int]) -> None:
        super().__init__(volume, size, "flying-edges")
        from vtkmodules.vtkFiltersCore import vtkPolyDataNormals, vtkWindowedSincPolyDataFilter

        self.name = "VTK flying edges + smoothing"
        self.filter.ComputeNormalsOff()
        self.smooth = vtkWindowedSincPolyDataFilter()
        self.smooth.SetInputConnection(self.filter.GetOutputPort())
        self.smooth.SetNumberOfIterations(20)
        self.smooth.SetPassBand(0.1)
        self.smooth.BoundarySmoothingOff()
        self.smooth.FeatureEdgeSmoothingOff()
        self.smooth.NonManifoldSmoothingOn()
        self.smooth.NormalizeCoordinatesOn()
        self.normals = vtkPolyDataNormals()
        self.normals.SetInputConnection(self.smooth.GetOutputPort())
        self.normals.SplittingOff()
        self.normals.ConsistencyOff()  # flying edges' triangles are consistently oriented
        self.normals.ComputePointNormalsOn()
        self.mapper.SetInputConnection(self.normals.GetOutputPort())

    def new_iso(self, iso: float, cam: sc.Camera) -> None:
        self.filter.SetValue(0, iso)
        self.normals.Update()
        self.win.render(cam)
        self.iso = iso

    def polydata(self):
        return self.normals.GetOutput()


class SkimageIso(_MeshIso):
    """scikit-image's marching cubes (Lewiner) with its gradient normals, rasterized by VTK."""

    name = "skimage marching cubes + VTK"

    def __init__(self, volume: sc.Volume, size: tuple[int, int]) -> None:
        super().__init__(volume, size)
        self.data = np.asarray(volume.data)
        self._pd = None

    def new_iso(self, iso: float, cam: sc.Camera) -> None:
        from skimage.measure import marching_cubes
        from vtkmodules.util import numpy_support
        from vtkmodules.vtkCommonCore import vtkPoints
        from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData

        verts, faces, normals, _ = marching_cubes(self.data, iso, spacing=self.volume.spacing)
        verts += np.asarray(self.volume.origin, np.float32)
        # scikit-image's normals may point against its triangles' winding (it depends on which
        # side is "inside"); VTK lights front faces with the given normal, so such a mesh renders
        # black. Turn the normals to agree with the winding, as a user has to.
        a, b, c = (verts[faces[:, i]] for i in range(3))
        winding = np.cross(b - a, c - a)
        if np.sum(winding * normals[faces[:, 0]]) < 0:
            normals = -normals
        pd = vtkPolyData()
        points = vtkPoints()
        points.SetData(numpy_support.numpy_to_vtk(verts.astype(np.float32), deep=True))
        pd.SetPoints(points)
        cells = vtkCellArray()
        offsets = np.arange(0, 3 * len(faces) + 1, 3, dtype=np.int64)
        cells.SetData(numpy_support.numpy_to_vtk(offsets, deep=True),
                      numpy_support.numpy_to_vtk(faces.astype(np.int64).ravel(), deep=True))
        pd.SetPolys(cells)
        vtk_normals = numpy_support.numpy_to_vtk(normals.astype(np.float32), deep=True)
        vtk_normals.SetName("Normals")
        pd.GetPointData().SetNormals(vtk_normals)
        self._pd = pd
        self.mapper.SetInputData(pd)
        self.win.render(cam)
        self.iso = iso

    def polydata(self):
        return self._pd

    def threads(self) -> dict[str, Any]:
        out = vtk_threads()
        out["skimage_threads"] = 1  # marching_cubes is single-threaded Cython
        return out


ISO_METHODS = {
    "splinecast": lambda vol, size: SplinecastIso(vol, size),
    "splinecast-exact-normals": lambda vol, size: SplinecastIso(vol, size, normals="exact"),
    "splinecast-s31": lambda vol, size: SplinecastIso(vol, size, "s31"),
    "splinecast-bspline3": lambda vol, size: SplinecastIso(vol, size, "bspline3"),
    "vtk-flying-edges": lambda vol, size: VtkContourIso(vol, size, "flying-edges"),
    "vtk-flying-edges-smoothed": lambda vol, size: VtkSmoothedIso(vol, size),
    "vtk-marching-cubes": lambda vol, size: VtkContourIso(vol, size, "marching-cubes"),
    "skimage-mc": lambda vol, size: SkimageIso(vol, size),
}

ISO_LABELS = {
    "splinecast": "splinecast exact (trilinear)",
    "splinecast-exact-normals": "splinecast exact (trilinear, the model's own normals)",
    "splinecast-s31": "splinecast exact (s31)",
    "splinecast-bspline3": "splinecast exact (bspline3)",
    "vtk-flying-edges": "VTK flying edges + render",
    "vtk-flying-edges-smoothed": "VTK flying edges + smoothing + render",
    "vtk-marching-cubes": "VTK marching cubes + render",
    "skimage-mc": "skimage marching cubes + VTK render",
}

#: The splinecast isosurface methods (they need neither VTK nor scikit-image).
SPLINECAST_ISO = ("splinecast", "splinecast-exact-normals", "splinecast-s31",
                  "splinecast-bspline3")


def iso_requirements(key: str) -> str | None:
    """Why an isosurface method cannot run here, or None when it can."""
    if key in SPLINECAST_ISO:
        return None
    status = vtk_status()
    if not status["available"]:
        return status["reason"]
    if key == "skimage-mc" and not skimage_status()["available"]:
        return skimage_status()["reason"]
    return None


# --------------------------------------------------------------------------- MIP / DVR

def splinecast_modes() -> tuple[str, ...]:
    """The render modes this splinecast build offers (checked at run time)."""
    from splinecast import scene

    return tuple(getattr(scene, "MODES", ("iso",)))


def dvr_transfer(volume: sc.Volume, iso: float) -> list[tuple[float, float]]:
    """The DVR opacity control points ``(value, alpha per voxel)`` shared by all methods.

    A ramp that starts a little below the isovalue of record and reaches 0.6 per voxel at the top
    of the data range: a semi-transparent shell around the object with a denser core.
    """
    lo, hi = volume.value_range
    span = hi - lo
    return [(lo, 0.0), (iso - 0.05 * span, 0.0), (iso + 0.05 * span, 0.15), (hi, 0.6)]


#: Opacity of a one-voxel slab that VTK's fixed-point caster stops a ray at: it ends a ray
#: once the remaining transparency, in its 15-bit fixed point, falls below 0xff (of 0x7fff).
VTK_FIXED_POINT_TERMINATION = 1.0 - 255.0 / 32768.0


def dense_transfers(volume: sc.Volume) -> dict[str, list[tuple[float, float]]]:
    """Dense DVR opacity control points ``(value, alpha per voxel)`` by name, the colour being
    the suite's grey ramp over the data range (colour does not change the work).

    ``"automatic"``: the opacity of :func:`splinecast.auto_transfer_function` (what
    ``mode="dvr"`` shows without a transfer function: a ramp from the automatic isovalue to 0.1
    at the 99.5th percentile of the values above it); ``"every voxel"``: a ramp from the lowest
    value to 0.1 per voxel at the highest, so every voxel above the background's value is partly
    visible and rays end by opacity, not by leaving the volume.
    """
    auto = sc.auto_transfer_function(volume)
    lo, hi = volume.value_range
    return {"automatic": [(float(v), float(a)) for v, a in auto.opacity_points],
            "every voxel": [(float(lo), 0.0), (float(hi), 0.1)]}


class VolumeMethod:
    """Base class of MIP / DVR methods."""

    name = ""

    def __init__(self, volume: sc.Volume, size: tuple[int, int], mode: str, iso: float,
                 step: float) -> None:
        self.volume, self.size, self.mode, self.iso, self.step = volume, size, mode, iso, step

    def frame(self, cam: sc.Camera) -> None:
        raise NotImplementedError

    def image(self, cam: sc.Camera) -> np.ndarray:
        """MIP: the projected value normalized to [0, 1] over the data range (h, w).
        DVR: premultiplied RGB in [0, 1] on black (h, w, 3)."""
        raise NotImplementedError

    def threads(self) -> dict[str, Any]:
        raise NotImplementedError

    def close(self) -> None:
        pass


class SplinecastVolume(VolumeMethod):
    """splinecast's own MIP / DVR (used only when ``splinecast.scene.MODES`` has the mode).

    MIP is the exact method unless ``method`` names a sampled one: ``"sampled"`` (every
    ``step`` voxels along the ray, the fixed-step sampling VTK's casters do) or ``"slices"``
    (on every ``step``-th voxel plane across the ray), matched to the tolerance like them; or
    ``"tolerance"``: the exact method with ``tolerance=step / 255`` (of the window), matched
    the same way (a larger "step", a larger tolerance, a faster frame).
    """

    def __init__(self, volume, size, mode, iso, step, method: str = "exact",
                 transfer: list[tuple[float, float]] | None = None,
                 termination: float | None = None) -> None:
        super().__init__(volume, size, mode, iso, step)
        self.name = f"splinecast {'' if method == 'exact' else method + ' '}{mode}"
        self.scene = sc.Scene(volume)
        params = inspect.signature(self.scene.render).parameters
        self.kwargs: dict[str, Any] = {"mode": mode}
        if method == "tolerance" and mode == "mip":
            self.kwargs.update(tolerance=step / 255.0)
        elif method != "exact" and mode == "mip":
            self.kwargs.update(method=method, step=step)
        if mode == "dvr":
            from splinecast.transfer import TransferFunction

            tf = TransferFunction(transfer or dvr_transfer(volume, iso), volume.value_range,
                                  "gray")
            for key in ("transfer", "transfer_function", "tf"):
                if key in params:
                    self.kwargs[key] = tf
                    break
            # Composite over black like VTK's renderer (splinecast's default background is a
            # dark grey), so the RGB is premultiplied colour over black.
            if "shading" in params:
                self.kwargs["shading"] = sc.Shading(background=(0.0, 0.0, 0.0, 1.0))
            # ``step`` > 0: that sample step (voxels), other settings at splinecast's defaults
            # (the settings ``mode="dvr"`` uses without ``dvr=``, where the build has them);
            # 0: splinecast's default settings.
            if step > 0 and "dvr" in params:
                import dataclasses

                from splinecast.render import dvr as dvr_module

                default = getattr(dvr_module, "DEFAULT_SETTINGS", dvr_module.DVRSettings())
                self.kwargs["dvr"] = dataclasses.replace(default, step=step)
            # ``termination``: the default settings with another early-termination opacity.
            if termination is not None:
                import dataclasses

                from splinecast.render.dvr import DEFAULT_SETTINGS

                base = self.kwargs.get("dvr", DEFAULT_SETTINGS)
                self.kwargs["dvr"] = dataclasses.replace(base, termination=termination)

    def _render(self, cam: sc.Camera, outputs: Any = None) -> sc.Frame:
        return self.scene.render(cam, **self.kwargs, outputs=outputs)

    def frame(self, cam: sc.Camera) -> None:
        # The timed frame fills the colour buffer alone, like the isosurface rows and like
        # VTK's casters, whose frame is an RGBA image (the per-pixel depth, position and ray
        # statistics splinecast can also return cost 15-20 ms a frame at 1024x768).
        self._render(cam, COLOUR)

    def image(self, cam: sc.Camera) -> np.ndarray:
        frame = self._render(cam, ("value",) if self.mode == "mip" else COLOUR)
        if self.mode == "mip":
            lo, hi = self.volume.value_range
            value = np.asarray(frame.value, np.float64)
            return np.where(np.isfinite(value), (value - lo) / (hi - lo), 0.0)
        # Front-to-back compositing over an opaque black background: RGB is premultiplied.
        return np.asarray(frame.rgba, np.float64)[..., :3]

    def threads(self) -> dict[str, Any]:
        return {"threads": splinecast_threads(), "what": "numba threads"}


class VtkVolume(VolumeMethod):
    """VTK's ray casters: the fixed-point CPU mapper or the OpenGL GPU mapper (on llvmpipe).

    Both get trilinear interpolation, a sample distance of ``step`` voxels along the ray, no
    automatic sample-distance or image-resolution adjustment, no jittering, and, for DVR, opacity
    given per voxel length (``ScalarOpacityUnitDistance`` = voxel size) so it means what
    splinecast's transfer function means.
    """

    def __init__(self, volume, size, mode, iso, step, mapper: str,
                 transfer: list[tuple[float, float]] | None = None) -> None:
        super().__init__(volume, size, mode, iso, step)
        from vtkmodules.vtkCommonDataModel import vtkPiecewiseFunction
        from vtkmodules.vtkRenderingCore import (
            vtkColorTransferFunction,
            vtkVolume,
            vtkVolumeProperty,
        )

        self.win = VtkWindow(size)
        voxel = float(min(volume.spacing))
        if mapper == "fixed-point":
            from vtkmodules.vtkRenderingVolume import vtkFixedPointVolumeRayCastMapper

            m = vtkFixedPointVolumeRayCastMapper()
            m.SetImageSampleDistance(1.0)
            m.SetInteractiveSampleDistance(step * voxel)
            self.name = f"VTK fixed-point CPU {mode}"
        else:
            from vtkmodules.vtkRenderingVolumeOpenGL2 import vtkOpenGLGPUVolumeRayCastMapper

            m = vtkOpenGLGPUVolumeRayCastMapper()
            m.SetLockSampleDistanceToInputSpacing(False)
            m.SetUseJittering(False)
            self.name = f"VTK GPU ray cast (llvmpipe) {mode}"
        m.SetAutoAdjustSampleDistances(False)
        m.SetSampleDistance(step * voxel)
        m.SetInputData(vtk_image(volume))
        if mode == "mip":
            m.SetBlendModeToMaximumIntensity()
        else:
            m.SetBlendModeToComposite()
        self.mapper = m
        lo, hi = volume.value_range
        color = vtkColorTransferFunction()
        color.AddRGBPoint(lo, 0.0, 0.0, 0.0)
        color.AddRGBPoint(hi, 1.0, 1.0, 1.0)
        opacity = vtkPiecewiseFunction()
        if mode == "mip":
            # Opaque grey ramp: the pixel's grey level is the normalized maximum.
            opacity.AddPoint(lo, 1.0)
            opacity.AddPoint(hi, 1.0)
        else:
            for value, alpha in transfer or dvr_transfer(volume, iso):
                opacity.AddPoint(value, alpha)
        prop = vtkVolumeProperty()
        prop.SetColor(color)
        prop.SetScalarOpacity(opacity)
        prop.SetInterpolationTypeToLinear()
        prop.ShadeOff()
        prop.SetScalarOpacityUnitDistance(voxel)
        self.actor = vtkVolume()
        self.actor.SetMapper(m)
        self.actor.SetProperty(prop)
        self.win.renderer.AddVolume(self.actor)
        self.mapper_kind = mapper

    def frame(self, cam: sc.Camera) -> None:
        self.win.render(cam)

    def image(self, cam: sc.Camera) -> np.ndarray:
        rgba = self.win.render(cam).astype(np.float64) / 255.0
        if self.mode == "mip":
            return rgba[..., 0]
        return rgba[..., :3]

    def threads(self) -> dict[str, Any]:
        out = vtk_threads()
        if self.mapper_kind == "fixed-point":
            out["fixed_point_threads"] = int(self.mapper.GetNumberOfThreads())
        return out

    def close(self) -> None:
        self.win.close()


VOLUME_METHODS = {
    "splinecast": lambda vol, size, mode, iso, step: SplinecastVolume(vol, size, mode, iso, step),
    "splinecast-sampled": lambda vol, size, mode, iso, step:
        SplinecastVolume(vol, size, mode, iso, step, method="sampled"),
    "splinecast-slices": lambda vol, size, mode, iso, step:
        SplinecastVolume(vol, size, mode, iso, step, method="slices"),
    "splinecast-tolerance": lambda vol, size, mode, iso, step:
        SplinecastVolume(vol, size, mode, iso, step, method="tolerance"),
    "vtk-fixed-point": lambda vol, size, mode, iso, step:
        VtkVolume(vol, size, mode, iso, step, "fixed-point"),
    "vtk-gpu": lambda vol, size, mode, iso, step: VtkVolume(vol, size, mode, iso, step, "gpu"),
}

VOLUME_LABELS = {
    "splinecast": "splinecast",
    "splinecast-sampled": "splinecast sampled",
    "splinecast-slices": "splinecast slices",
    "splinecast-tolerance": "splinecast exact within k/255 of the window (k: the step column)",
    "vtk-fixed-point": "VTK fixed-point CPU ray caster",
    "vtk-gpu": "VTK OpenGL ray caster on llvmpipe",
}


#: Settings tried when matching a method's quality, coarsest first, where they are not
#: ``runner.VOLUME_STEPS``: the tolerance row's k (k/255 of the window) has no voxel step's
#: limits, and its mean error is a fraction of k, so the ladder goes further.
VOLUME_METHOD_STEPS = {"splinecast-tolerance": (16.0, 12.0, 8.0, 6.0, 4.0, 3.0, 2.0, 1.0, 0.5)}

#: Modes each volume method takes part in (every mode when not listed). splinecast's DVR is
#: sampled already, so its ``splinecast`` row is the sampled one.
VOLUME_METHOD_MODES = {"splinecast-sampled": ("mip",), "splinecast-slices": ("mip",),
                       "splinecast-tolerance": ("mip",)}


def volume_keys(mode: str) -> list[str]:
    """The volume methods that render ``mode`` ("mip" or "dvr")."""
    return [k for k in VOLUME_METHODS if mode in VOLUME_METHOD_MODES.get(k, (mode,))]


def volume_requirements(key: str, mode: str) -> str | None:
    """Why a MIP/DVR method cannot run here, or None when it can."""
    if key in ("splinecast", "splinecast-sampled", "splinecast-slices", "splinecast-tolerance"):
        if mode not in splinecast_modes():
            return (f"splinecast has no mode {mode!r} yet (splinecast.scene.MODES = "
                    f"{splinecast_modes()})")
        return None
    status = vtk_status()
    return None if status["available"] else status["reason"]
