"""Run-time pieces both sides use: the executor (``parallel_map``), optional extras (``require``) and output
folders (``prepare_output_dir`` and friends), and ``gc_paused`` (no cyclic garbage collection during a block).

A bottom layer: it imports nothing of the planner, the controller or the certifier, so that ``tubempc.planning``
and ``verify`` can both use it without importing each other. Its errors: ``tubempc.runtime.errors``.
"""
