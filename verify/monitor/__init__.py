"""The MITL monitor: one three-valued robustness semantics, two implementations that give bit-identical values.

- ``engine``: the general interval engine on any positions (sample points and the gaps between them, or the
  points of a timed run); every formula of the grammar.
- ``grid``: the fast path for the trajectory semantics on a regular sample grid (cache-blocked window extrema);
  the certifier uses it when the samples are regular and falls back to ``engine`` otherwise.

The two semantics of the certifier that run on it live in ``verify.semantics``.
"""
