"""What the layers above ask of a mode's host object, beyond its compiled hooks.

Each mode's host class (:class:`~.iso.Iso`, :class:`~.multi_iso.MultiIso`, :class:`~.mip.Mip`,
:class:`~.dvr.Dvr`: parameters, buffers, the Frame) derives from :class:`ModeHost`. A scene kind
that renders a cut of bricks (a pyramid, a wavelet store, a Dask worker's share) asks the host
which bricks can show something, which values decide the level of detail, how seams close and
how partial images finish; it never tests which mode it holds. The base class gives the answers
of a mode that needs none of that; a mode overrides what differs in its own module.
"""

from __future__ import annotations

from collections.abc import Hashable

from ..transfer import TransferFunction

__all__ = ["ModeHost"]


class ModeHost:
    """Base of the modes' host objects: the questions of the scene kinds, with neutral answers."""

    #: The name :meth:`splinecast.Scene.render` knows the mode by.
    name: str = ""
    #: Whether a sort-last render refines the depth of its pixels after compositing (DVR: the
    #: depth where the opacity in front of a share's first sample crosses the threshold).
    refines_depth_after_compositing: bool = False
    #: Whether the frame's surface effects (:class:`~splinecast.render.effects.SurfaceEffects`)
    #: are applied on the host from the hit's position, normal and face after tracing (the
    #: first-hit isosurface; several isosurfaces apply them in their kernels).
    effects_after_tracing: bool = False
    #: Whether the mode's rays go deep into the volume (they do not stop at a first hit), so
    #: rays of neighbouring tiles share many voxels: a thread then traces the model's work
    #: items of several bands (``work_rows``) a column of tiles at a time, while the voxels
    #: they share are in the cache. Rays that stop at a surface gain nothing from it.
    deep_rays: bool = False

    def blocks_key(self) -> Hashable | None:
        """What the mode's block selection (``blocks``) depends on besides the grid; None when
        unknown (then a renderer that caches the selection recomputes it every frame)."""
        return None

    def surface_values(self) -> float | list[float] | None:
        """The isovalue(s) whose crossings the mode draws (a brick no surface crosses is left
        out; the wavelet selection refines around them); None for the other modes."""
        return None

    def first_hit_iso(self) -> float | None:
        """The isovalue of a first-hit isosurface, whose gaps at level boundaries are closed
        (:class:`splinecast.multires.draw.seams.IsoClosure`); None: no closure."""
        return None

    def visible_transfer(self) -> TransferFunction | None:
        """The transfer function whose transparent ranges leave a brick out (None: no such
        filter; the projections look at every brick)."""
        return None

    def cut_transfer(self) -> TransferFunction | None:
        """The classification an error-metric cut measures the image's distortion with (None:
        the level-of-detail cut serves the mode)."""
        return None
