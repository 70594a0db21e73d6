"""Side-by-side comparison of splinecast with VTK and scikit-image.

Run from the repository root::

    python -m benchmarks.compare            # full suite, results in benchmarks/results/compare.*
    python -m benchmarks.compare --quick    # 64^3 volumes, 128x128 images (what the tests run)

Modules: :mod:`.scenes` (volumes, isovalues, analytic truth), :mod:`.metrics` (surface position
and normal errors, z-buffer conversion), :mod:`.methods` (one class per rendering method, all with
the same small interface), :mod:`.runner` (interleaved timing, quality, per-method memory in
subprocesses) and :mod:`.report` (JSON, markdown, plots).
"""
