"""The run-time kit the planner and the certifier share: the executor (``parallel_map``), optional extras
(``require``), output folders (``prepare_output_dir`` and friends), ``gc_paused`` (no cyclic garbage collection
during a block) and their errors (``runkit.errors``).

The bottom layer: it imports nothing of ``tubempc`` or ``verify``, so that both can use it without importing each
other (``tests/test_boundary.py`` holds it to that).
"""
