"""Brick pyramids in OME-Zarr stores: building them, their per-brick tables and histograms, and the
RAM caches of chunks and bricks."""
