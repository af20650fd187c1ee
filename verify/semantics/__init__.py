"""The certifier's two semantics of a formula on a log, both evaluated by ``verify.monitor``.

- ``trajectory``: the stricter one: atoms along the continuous trajectory (samples plus a bound on the motion
  between two samples); its verdict is the ``spec_trajectory`` check.
- ``timed_run``: the paper's (Definition 3): the run of regions that fully contain the robot disc, judged pointwise;
  its verdict is the ``spec_timed_run`` check.

The planner has a third evaluator of the same pointwise semantics, ``tubempc.planning.reference_semantics`` (exact,
on lasso runs), which the property tests compare with ``timed_run``.
"""
