"""Test-session set-up shared by every suite: hypothesis profiles, a temporary abstraction cache, and the check that
every certificate the tests write matches the published schema.

Profiles, chosen with HYPOTHESIS_PROFILE=dev|ci|nightly (default dev). ci: derandomized (reproducible in CI), modest
example counts so that the whole property suite stays within five minutes on two cores; nightly: many more examples,
for scheduled runs, with the example database kept in ``.hypothesis/nightly`` (or $HYPOTHESIS_DATABASE) so that a
failure found one night is replayed first the next, and ``print_blob`` on.

Cache: the WTS abstraction is cached on disk (``$TUBEMPC_CACHE``, default ``~/.cache/tubempc``). Tests must not read
a cache left warm by an earlier run or write into the user's home, so every test session gets a fresh temporary
cache folder of its own (each xdist worker too); set TUBEMPC_TEST_CACHE to a folder to reuse one on purpose.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings
from hypothesis.database import DirectoryBasedExampleDatabase

settings.register_profile("dev", max_examples=50, deadline=None)
settings.register_profile(
    "ci",
    max_examples=40,
    deadline=None,
    derandomize=True,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.register_profile(
    "nightly",
    max_examples=1000,
    deadline=None,
    print_blob=True,
    database=DirectoryBasedExampleDatabase(
        os.environ.get("HYPOTHESIS_DATABASE", str(Path(__file__).parent / ".hypothesis" / "nightly"))),
    suppress_health_check=[HealthCheck.too_slow],
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "dev"))

_SESSION_CACHE: tempfile.TemporaryDirectory[str] | None = None


def pytest_configure(config: pytest.Config) -> None:
    """Point the abstraction cache at a fresh temporary folder for this test session."""
    global _SESSION_CACHE  # noqa: PLW0603 - one folder per session, removed at its end
    chosen = os.environ.get("TUBEMPC_TEST_CACHE")
    if chosen:
        os.environ["TUBEMPC_CACHE"] = chosen
        return
    _SESSION_CACHE = tempfile.TemporaryDirectory(prefix="tubempc-test-cache-")
    os.environ["TUBEMPC_CACHE"] = _SESSION_CACHE.name


def pytest_unconfigure(config: pytest.Config) -> None:
    if _SESSION_CACHE is not None:
        _SESSION_CACHE.cleanup()


@pytest.fixture(scope="session", autouse=True)
def _written_certificates_match_the_schema(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """After the session: every ``certificate.json`` any test wrote under the session's temporary folders (in
    process or by a ``tubempc`` subprocess) is validated against the published JSON Schema of the certificate."""
    yield
    # a symbolic link named certificate.json is a test's decoy (outputs never write through one), not a certificate
    files = sorted(p for p in tmp_path_factory.getbasetemp().rglob("certificate.json") if not p.is_symlink())
    if not files:
        return
    import json

    import jsonschema

    from verify.certificate import certificate_schema

    validator = jsonschema.Draft202012Validator(certificate_schema())
    bad = []
    for path in files:
        try:
            errors = [e.message for e in validator.iter_errors(json.loads(path.read_text(encoding="utf-8")))]
        except (OSError, ValueError) as err:
            errors = [f"unreadable: {err}"]
        if errors:
            bad.append(f"{path}: {errors[0]}")
    if bad:
        pytest.fail(f"{len(bad)} of {len(files)} certificate(s) written by the tests break the schema:\n"
                    + "\n".join(bad[:10]))


@pytest.fixture(params=["fast", "rosbags"])
def ingest_path(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    """Run a test twice: with the certifier's own fast readers (the default) and with ``TUBEMPC_FAST_INGEST=0``
    (every log read by plain rosbags); the test's assertions must hold both ways."""
    monkeypatch.setenv("TUBEMPC_FAST_INGEST", "1" if request.param == "fast" else "0")
    return str(request.param)
