"""Optional dependencies: each extra's entry point, with that extra's module missing, is one stderr line naming the
extra and exit 4 (feature not available), never an ImportError traceback; the base install certifies without them.

A missing module is simulated by ``sys.modules[name] = None`` (what Python does for a blocked import: ``import name``
raises ImportError); ``runkit.extras`` must see it as missing even when the module was imported earlier.
"""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path

import pytest

from runkit.errors import MissingExtraError
from runkit.extras import EXTRAS, missing_modules, require
from tubempc.cli import main
from tubempc.scenario import builtin_scenario

ROOT = Path(__file__).resolve().parent.parent
LOG = ROOT / "logs" / "late_mission.mcap"


def _block(monkeypatch: pytest.MonkeyPatch, *names: str) -> None:
    for name in names:
        monkeypatch.setitem(sys.modules, name, None)


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    with pytest.raises(SystemExit) as exc:
        main(argv)
    code = exc.value.code
    return (code if isinstance(code, int) else 0), capsys.readouterr().err


def _one_line_naming(err: str, extra: str, *needles: str) -> None:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("tubempc: error: ") and "Traceback" not in err, err
    assert f"'{extra}' extra" in lines[0] or f"'{extra}' and" in lines[0] or f"and '{extra}'" in lines[0], err
    assert f"tubempc[{extra}" in lines[0] or f",{extra}" in lines[0], err
    for needle in needles:
        assert needle in lines[0], (needle, err)


def test_require_names_the_extra_and_passes_when_installed(monkeypatch: pytest.MonkeyPatch) -> None:
    for extra in EXTRAS:
        assert missing_modules(extra) == [], f"the test environment installs every extra ({extra})"
        require(extra, feature="x")
    _block(monkeypatch, "matplotlib", "networkx")
    assert missing_modules("report") == ["matplotlib"]
    with pytest.raises(MissingExtraError, match=r"^the demo needs networkx, matplotlib, which are not installed: "
                                                r"install the 'plan' and 'report' extras \(pip install "
                                                r"'tubempc\[plan,report\]'"):
        require("plan", "report", feature="the demo")
    with pytest.raises(ImportError):  # an ImportError too, for code that catches those
        require("report", feature="report.html", alternative="pass --no-report")
    with pytest.raises(ValueError, match="extra='reports' is not one of"):
        missing_modules("reports")


def test_report_writing_without_matplotlib(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    _block(monkeypatch, "matplotlib")
    out = tmp_path / "run"
    code, err = _run(["certify", str(LOG), "--scenario", "nexus-sml", "--out", str(out)], capsys)
    assert code == 4
    _one_line_naming(err, "report", "matplotlib", "--no-report")
    assert not out.exists() or not any(out.iterdir())  # refused before any work
    # what the base install does: certify, the certificate only
    code, err = _run(["certify", str(LOG), "--scenario", "nexus-sml", "--out", str(out), "--no-report"], capsys)
    assert code == 1 and (out / "certificate.json").is_file(), err
    code, err = _run(["certify", str(LOG), str(ROOT / "logs" / "tube_breach.mcap"), "--scenario", "nexus-sml",
                      "--out", str(tmp_path / "batch"), "--no-report", "--workers", "1"], capsys)
    assert code == 1 and (tmp_path / "batch" / "summary.md").is_file(), err
    from verify.batch import BatchResult, write_batch

    with pytest.raises(MissingExtraError, match=r"report\.html needs matplotlib.*'report' extra"):
        write_batch(BatchResult((), builtin_scenario(), None), tmp_path / "api")


def test_dask_batch_without_dask(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                 capsys: pytest.CaptureFixture[str]) -> None:
    _block(monkeypatch, "dask", "distributed")
    code, err = _run(["certify", str(LOG), "--scenario", "nexus-sml", "--dask", "local"], capsys)
    assert code == 4
    _one_line_naming(err, "dask", "--dask", "distributed")
    from verify.batch import parallel_map

    with pytest.raises(MissingExtraError, match=r"'dask' extra"):
        parallel_map(abs, [1, -2], dask="local")


def test_strategies_without_hypothesis(monkeypatch: pytest.MonkeyPatch) -> None:
    _block(monkeypatch, "hypothesis", "hypothesis.strategies")
    for name in [m for m in sys.modules if m == "tubempc.strategies" or m.startswith("tubempc.strategies.")]:
        monkeypatch.delitem(sys.modules, name)
    with pytest.raises(MissingExtraError, match=r"^tubempc\.strategies needs hypothesis.*'testing' extra"):
        importlib.import_module("tubempc.strategies")


@pytest.mark.parametrize(("argv", "extra", "blocked"), [
    (["plan", "--scenario", "nexus-sml"], "plan", "networkx"),
    (["simulate", "--scenario", "nexus-sml", "--to", "R3", "--out", "x.mcap"], "plan", "casadi"),
    (["falsify", "--scenario", "nexus-sml", "--from", "R1", "--to", "R3", "--method", "optimizer"], "plan", "scipy"),
    (["falsify", "--scenario", "nexus-sml", "--from", "R1", "--to", "R3"], "testing", "hypothesis"),
    (["regress"], "plan", "cvxpy"),
    (["demo"], "report", "matplotlib"),
    (["demo"], "plan", "casadi"),
    (["plan", "--scenario", "nexus-sml", "--dask", "local"], "dask", "distributed"),
])
def test_planning_commands_without_their_extra(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, *,
                                               capsys: pytest.CaptureFixture[str], argv: list[str], extra: str,
                                               blocked: str) -> None:
    monkeypatch.chdir(tmp_path)
    _block(monkeypatch, blocked)
    code, err = _run(argv, capsys)
    assert code == 4, err
    _one_line_naming(err, extra, blocked)
    assert list(tmp_path.iterdir()) == []  # refused before any work


def test_certification_imports_no_optional_module() -> None:
    """The base install: the CLI starts and certifies a log (no reports) without any optional module importable."""
    blocked = [name for names in EXTRAS.values() for name in names]
    code = ("import sys\n"
            f"for name in {blocked!r}:\n"
            "    sys.modules[name] = None\n"
            "from tubempc.cli import main\n"
            "main(sys.argv[1:])\n")
    proc = subprocess.run([sys.executable, "-c", code, "certify", str(LOG), "--scenario", "nexus-sml", "--json"],
                          capture_output=True, text=True, timeout=120, check=False, cwd=ROOT)
    assert proc.returncode == 1, proc.stderr
    assert '"verdict": "fail"' in proc.stdout and "Traceback" not in proc.stderr
