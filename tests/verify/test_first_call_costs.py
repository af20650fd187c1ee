"""``verify.ingest.stats.median``: numpy's median, value for value, without importing ``numpy.ma`` (which
``np.median`` of floating values does on first use: ~12 ms of CPU in every fresh process that certifies); and
certifying a ROS1 or sqlite3 log never imports it."""

from __future__ import annotations

import json
import subprocess
import sys
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tubempc.scenario import Scenario
from verify.ingest.stats import median

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("seed", range(4))
def test_median_is_numpys(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for n in range(1, 12):
        for a in (rng.integers(-(10**18), 10**18, n, dtype=np.int64), rng.normal(size=n),
                  rng.choice(np.array([np.inf, -np.inf, 1.0, 2.0, np.nan]), n)):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # inf - inf, as numpy's own mean warns
                want, got = np.median(a), median(a)
                rows = np.stack([a, a[::-1]]).astype(np.float64)
                want_rows, got_rows = np.median(rows, axis=1), median(rows, axis=1)
            assert type(got) is type(want) and (got == want or (np.isnan(got) and np.isnan(want))), (a, want, got)
            assert np.array_equal(got_rows, want_rows, equal_nan=True) and got_rows.dtype == want_rows.dtype


@pytest.mark.parametrize("fmt", ["bag", "dir-sqlite3"])
def test_certifying_does_not_import_numpy_ma(make_log: Callable[..., Path], paper_traj: Callable[..., Any],
                                             scenario: Scenario, fmt: str) -> None:
    """(MCAP's chunk reader still calls ``np.unique``, which imports it too.)"""
    log = make_log(fmt, paper_traj(scenario, end_s=5.0))
    code = ("import sys; from tubempc.scenario import builtin_scenario; from verify.certify import certify_log; "
            f"certify_log({str(log)!r}, builtin_scenario()); print('numpy.ma' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True,
                         env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "HOME": str(Path.home())})
    assert out.stdout.strip().splitlines()[-1] == "False", out.stderr[-400:]


def test_the_certificate_model_built_in_the_background_is_the_one_used(make_log: Callable[..., Path],
                                                                        paper_traj: Callable[..., Any],
                                                                        scenario: Scenario) -> None:
    """certify builds the certificate model in a background thread while it reads the log (pydantic's schema, ~4
    ms of a first call's judging): once per process, and whatever uses the model meanwhile -- certify in four
    threads at once, a validation and the schema while it builds -- waits for it and gets what a process that
    never built it in the background gets."""
    log = make_log("bag", paper_traj(scenario, end_s=5.0))
    code = f"""
import json, sys, threading
from tubempc.scenario import builtin_scenario
from verify import certificate
from verify.certify import certify_log
background = sys.argv[1] == "1"
if not background:
    certificate.build_in_background = lambda: None
    import verify.certify
    verify.certify.build_in_background = certificate.build_in_background
out = []
def run():
    out.append(certify_log({str(log)!r}, builtin_scenario()).certificate)
threads = [threading.Thread(target=run) for _ in range(4)]
[t.start() for t in threads]
[t.join() for t in threads]
certificate.build_in_background()
again = certificate.Certificate.model_validate(out[0]).to_json_dict()
schema = certificate.certificate_schema()
print(json.dumps([out, again, schema, len(certificate._builder)]))
"""
    got = {}
    for background in ("1", "0"):
        run = subprocess.run([sys.executable, "-c", code, background], capture_output=True, text=True, cwd=ROOT,
                             check=True, env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin",
                                              "HOME": str(Path.home())})
        got[background] = json.loads(run.stdout.strip().splitlines()[-1])
    certs, again, schema, builders = got["1"]
    assert builders == 1  # one background build for the four certify calls
    assert got["0"][3] == 0
    assert all(c == certs[0] for c in certs) and again == certs[0]
    assert [certs[0], schema] == [got["0"][0][0], got["0"][2]]
