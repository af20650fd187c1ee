"""The CLI frame: help lists the subcommands; errors become one stderr line and a documented exit code."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from tubempc.cli import EXIT_UNUSABLE


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "tubempc", *args], capture_output=True, text=True, timeout=120,
                          check=False)


def test_help_lists_subcommands() -> None:
    out = run("--help")
    assert out.returncode == 0
    for name in ("certify", "plan", "simulate", "regress", "demo", "scenario", "spec"):
        assert name in out.stdout


def test_spec_error_is_one_line_exit_3() -> None:
    out = run("spec", "F[1,2 a")
    assert out.returncode == EXIT_UNUSABLE
    assert out.stderr.strip().count("\n") == 0
    assert "column 7" in out.stderr and "Traceback" not in out.stderr


def test_spec_canonical() -> None:
    out = run("spec", "G[0,inf)!(obs_1|obs_2)&F[30,50]m")
    assert out.returncode == 0
    assert out.stdout.strip() == "G[0,inf) !(obs_1 | obs_2) & F[30,50] m"


def test_scenario_show_and_validate(tmp_path: Path) -> None:
    out = run("scenario", "show")
    assert out.returncode == 0 and "nexus-sml" in out.stdout
    path = tmp_path / "mine.yaml"
    path.write_text(out.stdout)
    ok = run("scenario", "validate", str(path))
    assert ok.returncode == 0 and "9 regions" in ok.stdout
    path.write_text(out.stdout.replace("radius: 0.27", "radius: -1"))
    bad = run("scenario", "validate", str(path))
    assert bad.returncode == EXIT_UNUSABLE
    assert str(path) in bad.stderr and "robot.radius" in bad.stderr
    assert bad.stderr.strip().count("\n") == 0


@pytest.mark.parametrize("args", [("scenario", "validate", "/nonexistent/s.yaml")])
def test_missing_file(args: tuple[str, ...]) -> None:
    out = run(*args)
    assert out.returncode == EXIT_UNUSABLE and "file not found" in out.stderr


def test_version_short_and_long() -> None:
    for flag in ("-V", "--version"):
        out = run(flag)
        assert out.returncode == 0 and out.stdout.startswith("tubempc, version ")


def test_scenario_list_and_unknown_scenario_name_lists_builtins() -> None:
    listed = run("scenario", "list")
    assert listed.returncode == 0 and listed.stdout.startswith("nexus-sml: 9 regions")
    out = run("plan", "--scenario", "nope")
    assert out.returncode == EXIT_UNUSABLE and out.stderr.count("\n") == 1
    assert "nope" in out.stderr and "nexus-sml" in out.stderr and "scenario list" in out.stderr


def test_quiet_and_verbose_on_every_command() -> None:
    import click

    from tubempc.cli import cli

    def walk(cmd: object, path: str) -> list[tuple[str, object]]:
        if not isinstance(cmd, click.Group):
            return [(path, cmd)]
        ctx = click.Context(cmd)
        subs = {name: cmd.get_command(ctx, name) for name in cmd.list_commands(ctx)}
        return [(path, cmd)] + [p for name, sub in subs.items() for p in walk(sub, f"{path} {name}")]

    for path, cmd in walk(cli, "tubempc"):
        opts = {o for p in getattr(cmd, "params", []) for o in getattr(p, "opts", [])}
        assert {"-q", "--quiet", "-v", "--verbose"} <= opts, path
    assert run("spec", "-q", "a & F[1,2] b").stdout.strip() == "a & F[1,2] b"  # asked-for output stays
    quiet = run("scenario", "validate", "-q", "nexus-sml")
    assert quiet.returncode == 0 and quiet.stdout == ""
    assert run("-q", "scenario", "validate", "nexus-sml").stdout == ""


def test_plan_impossible_design_is_exit_3_naming_the_file(tmp_path: Path) -> None:
    text = run("scenario", "show").stdout
    path = tmp_path / "heavy.yaml"
    path.write_text(text.replace("bound: 0.02}", "bound: 5.0}"))
    out = run("plan", "--scenario", str(path), "--no-cache")
    assert out.returncode == EXIT_UNUSABLE and str(path) in out.stderr and "cannot be designed" in out.stderr
    assert out.stderr.strip().count("\n") == 0


def test_simulate_impossible_design_is_exit_3_naming_the_file(tmp_path: Path) -> None:
    text = run("scenario", "show").stdout
    path = tmp_path / "heavy.yaml"
    path.write_text(text.replace("bound: 0.02}", "bound: 5.0}"))
    out = run("simulate", "--scenario", str(path), "--to", "R2", "--out", str(tmp_path / "x.mcap"))
    assert out.returncode == EXIT_UNUSABLE and str(path) in out.stderr and "cannot be designed" in out.stderr
    assert out.stderr.strip().count("\n") == 0 and not (tmp_path / "x.mcap").exists()


HEAVY = ("pandas", "matplotlib", "casadi", "cvxpy", "networkx")


@pytest.mark.parametrize("args", [["-V"], ["--help"]])
def test_version_and_help_import_no_heavy_module(args: list[str]) -> None:
    """Each subcommand's module is imported when it runs: -V and --help load neither the planner nor the
    certifier (a new user's first commands answer at once; benchmarks/bench_cli.py times them)."""
    probe = ("import sys\nfrom tubempc.cli import main\ntry:\n    main(sys.argv[1:])\nexcept SystemExit:\n    pass\n"
             f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", probe, *args], capture_output=True, text=True, timeout=120,
                         check=False)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "[]"


def test_certify_json_imports_no_plotting_or_planning_module() -> None:
    """certify --json writes no report: pandas and matplotlib (reports), casadi, cvxpy, networkx (planner) stay out."""
    log = Path(__file__).resolve().parents[1] / "logs" / "demo.mcap"
    probe = ("import sys\nfrom tubempc.cli import main\ntry:\n    main(sys.argv[1:])\nexcept SystemExit as e:\n"
             f"    code = e.code\nprint(code, sorted(m for m in {HEAVY!r} if m in sys.modules), file=sys.stderr)")
    out = subprocess.run([sys.executable, "-c", probe, "certify", str(log), "--scenario", "nexus-sml", "--json"],
                         capture_output=True, text=True, timeout=300, check=False)
    assert out.stderr.strip().splitlines()[-1] == "0 []", out.stderr


ROS2_ONLY = ("rosbags.rosbag2", "ruamel.yaml", "verify.ingest.mcap", "verify.ingest.mcapfile", "verify.ingest.sqlite")


def test_certify_of_a_ros1_bag_imports_nothing_ros2() -> None:
    """A ROS1 bag needs neither rosbags.rosbag2 (nor the YAML library it loads) nor the MCAP and sqlite3 readers:
    they are imported for the logs that need them (``verify.ingest.raw``), so certify --json starts sooner."""
    root = Path(__file__).resolve().parents[1]
    probe = ("import sys\nfrom tubempc.cli import main\ntry:\n    main(sys.argv[1:])\nexcept SystemExit as e:\n"
             f"    code = e.code\nprint(code, sorted(m for m in {ROS2_ONLY!r} if m in sys.modules), file=sys.stderr)")
    out = subprocess.run([sys.executable, "-c", probe, "certify", str(root / "logs" / "diffdrive_odom.bag"),
                          "--scenario", str(root / "docs" / "examples" / "diffdrive-room.yaml"), "--json"],
                         capture_output=True, text=True, timeout=300, check=False)
    assert out.stderr.strip().splitlines()[-1] == "0 []", out.stderr
    # and a ROS2 log still gets them (the same command on the demo MCAP log passes)
    mcap = subprocess.run([sys.executable, "-c", probe, "certify", str(root / "logs" / "demo.mcap"), "--scenario",
                           "nexus-sml", "--json"], capture_output=True, text=True, timeout=300, check=False)
    assert mcap.stderr.strip().splitlines()[-1].startswith("0 ['rosbags.rosbag2'"), mcap.stderr


@pytest.mark.parametrize(("call", "frozen"), [("main()", True), ("main(['spec', 'F[0,1] a'])", False)])
def test_only_a_one_command_process_freezes_its_imports(call: str, frozen: bool) -> None:
    """``tubempc`` (``main()``) freezes the command's imported modules out of garbage collection (the process runs
    one command); a caller that runs commands in its own process (``main(argv)``: tests, tools) keeps its collector
    as it was."""
    probe = ("import gc, sys\nfrom tubempc.cli import main\nsys.argv = ['tubempc', 'spec', 'F[0,1] a']\n"
             f"try:\n    {call}\nexcept SystemExit:\n    pass\nprint(gc.get_freeze_count() > 0)")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, check=False)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == str(frozen)


def test_certify_and_watch_share_their_judging_options() -> None:
    """``--checks``, ``--clock-offset`` and ``--scenario`` read alike in certify and watch: one definition each."""
    from tubempc.cli.certify import certify
    from tubempc.cli.watch import watch

    def declared(command: object) -> dict[str, tuple[object, ...]]:
        params = command.params  # type: ignore[attr-defined]
        return {p.name: (p.opts, p.metavar, p.multiple, p.help) for p in params
                if p.name in ("checks_text", "clock_offsets", "scenario")}

    assert declared(certify) == declared(watch)
    assert len(declared(certify)) == 3
