"""Certifying a ``LogData`` leaves it as it was: the certificate's notes are the certificate's own."""

from __future__ import annotations

import copy
from pathlib import Path

from tubempc.scenario import builtin_scenario
from verify import certify_data
from verify.ingest import read_log

LOG = Path(__file__).resolve().parents[2] / "logs" / "demo.mcap"
NOTE = "the log's metadata names a different scenario_sha256 than the scenario given to the certifier"


def test_a_scenario_mismatch_note_is_in_the_certificate_and_not_in_the_log() -> None:
    base = builtin_scenario()
    other = base.model_copy(update={"name": "nexus-sml-renamed"})  # another sha256 than the log's metadata names
    assert other.sha256() != base.sha256()
    log = read_log(LOG, other)
    assert log.metadata and log.metadata.get("scenario_sha256") == base.sha256()
    before = copy.deepcopy(log.data_quality)
    first = certify_data(log, other)
    second = certify_data(log, other)
    assert log.data_quality == before
    for result in (first, second):
        assert result.certificate["data_quality"]["notes"].count(NOTE) == 1
        assert result.typed.data_quality == result.certificate["data_quality"]
