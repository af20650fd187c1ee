"""Hypothesis profiles for all test suites, chosen with HYPOTHESIS_PROFILE=dev|ci|nightly (default dev).

ci: derandomized (reproducible in CI), modest example counts so that the whole property suite stays within
five minutes on two cores; nightly: many more examples, for scheduled runs.
"""

from __future__ import annotations

import os

from hypothesis import HealthCheck, settings

settings.register_profile("dev", max_examples=50, deadline=None)
settings.register_profile(
    "ci",
    max_examples=40,
    deadline=None,
    derandomize=True,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.register_profile("nightly", max_examples=1000, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "dev"))
