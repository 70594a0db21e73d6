"""Multiresolution: pyramids, brick octrees, cuts and spline wavelets (see DESIGN.md)."""
