"""Fuzzing harness: hostile files of every readable format and command-line options at their edges.

``python -m fuzz.run`` (from ``tests/``) builds small valid seed files of every format
(:mod:`fuzz.seeds`), mutates them byte by byte and field by field (:mod:`fuzz.mutations`), turns
them and the command-line options into cases (:mod:`fuzz.cases`) and runs every case in a forked
child of a pre-imported, pre-compiled parent under an address-space cap, a memory cap and a
timeout, classifying what happened (:mod:`fuzz.harness`). ``make test`` runs a short run through
``test_short_run.py``; ``make fuzz`` a long one.
"""
