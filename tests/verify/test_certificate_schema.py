"""The certificate is a typed contract: the model, its published JSON Schema (docs/certificate.schema.json, printed
by `tubempc schema certificate`), and what certify writes and prints all agree."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import jsonschema
import pytest
from pydantic import ValidationError

from tubempc.scenario import Scenario
from verify.certificate import CERTIFICATE_VERSION, Certificate, Verdict, certificate_schema
from verify.certify import certify_log, write_certificate

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def certificate(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    from tubempc.scenario import builtin_scenario

    result = certify_log(ROOT / "logs" / "obstacle_touch.bag", builtin_scenario())
    path = write_certificate(result, tmp_path_factory.mktemp("schema"))
    data: dict[str, Any] = json.loads(path.read_text())
    return data


def test_published_schema_is_the_models() -> None:
    published = json.loads((ROOT / "docs" / "certificate.schema.json").read_text())
    assert published == certificate_schema(), "regenerate: tubempc schema certificate > docs/certificate.schema.json"
    cli = subprocess.run([sys.executable, "-m", "tubempc", "schema", "certificate"], capture_output=True, text=True,
                         check=True, timeout=120)
    assert json.loads(cli.stdout) == published


def test_written_certificate_validates_and_round_trips(certificate: dict[str, Any]) -> None:
    jsonschema.validate(certificate, certificate_schema())
    model = Certificate.model_validate(certificate)
    assert model.certificate_version == CERTIFICATE_VERSION == 5
    assert model.verdict is Verdict.FAIL and model.to_json_dict() == certificate
    clearance = model.check("obstacle_clearance")
    assert clearance is not None and clearance.details["region"] == "R8"


def test_schema_refuses_what_the_contract_forbids(certificate: dict[str, Any]) -> None:
    validator = jsonschema.Draft202012Validator(certificate_schema())
    assert not list(validator.iter_errors(certificate))
    assert list(validator.iter_errors({**certificate, "verdict": "passed"}))  # verdicts are an enum
    assert list(validator.iter_errors({**certificate, "surprise": 1}))  # no field the schema does not name
    assert list(validator.iter_errors({**certificate, "certificate_version": 3}))
    failed = next(c for c in certificate["checks"] if c["verdict"] == "fail")
    no_margin = {**certificate, "checks": [{**{k: v for k, v in failed.items() if k != "margin_reason"},
                                            "margin": None}]}
    with pytest.raises(ValidationError, match="without a margin and without a margin_reason"):
        Certificate.model_validate(no_margin)
    Certificate.model_validate({**certificate, "checks": [{**failed, "margin": None,
                                                           "margin_reason": "-inf: overflowed"}]})
    no_time = {**certificate, "checks": [{**failed, "first_violation_time": None}]}
    with pytest.raises(ValidationError, match="without a first violation time"):
        Certificate.model_validate(no_time)


def test_write_certificate_refuses_a_certificate_that_breaks_the_model(tmp_path: Path,
                                                                       certificate: dict[str, Any]) -> None:
    broken = SimpleNamespace(certificate={**certificate, "verdict": "maybe"})
    with pytest.raises(ValidationError):
        write_certificate(broken, tmp_path)
    assert not (tmp_path / "certificate.json").exists()


def test_json_output_validates(scenario: Scenario) -> None:
    out = subprocess.run([sys.executable, "-m", "tubempc", "-q", "certify", str(ROOT / "logs" / "late_mission.mcap"),
                          "--scenario", "nexus-sml", "--json"], capture_output=True, text=True, timeout=120,
                         check=False)
    assert out.returncode == 1
    document = json.loads(out.stdout)
    jsonschema.validate(document, certificate_schema())
    late = Certificate.model_validate(document).check("spec_timed_run")
    assert late is not None and late.margin_unit == "s" and late.margin is not None and late.margin < 0
