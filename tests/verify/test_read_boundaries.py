"""Where reading meets the outside world: our own bugs are exit 70 (never "unreadable log"), special files inside a
bag folder are refused before they are opened, batch discovery ends on symlink loops, and a cut storage file inside
a bag folder is named and salvaged as the bare file is."""

from __future__ import annotations

import os
import shutil
import threading
import time
from pathlib import Path
from typing import Any

import pytest
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from tests.verify.test_damaged_input import FUZZ, SPEC, one_line_error, run
from verify.batch.run import discover_logs
from verify.ingest import log as log_module

STORE = get_typestore(Stores.ROS2_HUMBLE)


@pytest.fixture(scope="module")
def seeds(tmp_path_factory: pytest.TempPathFactory) -> dict[tuple[str, bool], Path]:
    out: dict[tuple[str, bool], Path] = FUZZ.write_seeds(tmp_path_factory.mktemp("seeds"))
    return out


def _mcap_folder(src: Path, dst: Path) -> Path:
    """The messages of the bare MCAP ``src`` as a ROS2 bag folder with MCAP storage (``dst/dst.mcap``)."""
    with Reader(src) as r, Writer(dst, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = {c.id: w.add_connection(c.topic, c.msgtype, typestore=STORE) for c in r.connections}
        for c, t, data in r.messages():
            w.write(conns[c.id], t, data)
    return dst


def test_a_type_error_in_the_quality_code_is_an_internal_error(seeds: dict[tuple[str, bool], Path],
                                                                monkeypatch: pytest.MonkeyPatch,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    """A bug of ours raised while a log is read is exit 70 with the traceback under --debug, not "unreadable log"
    (exit 3): the read boundary catches library errors only."""
    def broken(*args: Any, **kwargs: Any) -> Any:
        raise TypeError("a bug in the pose findings")

    monkeypatch.setattr(log_module, "pose_findings", broken)
    path = str(seeds["mcap", False])
    code, _, err = run(["certify", path, "--scenario", "nexus-sml", "--spec", SPEC], capsys)
    assert code == 70, err
    code, _, err = run(["--debug", "certify", path, "--scenario", "nexus-sml", "--spec", SPEC], capsys)
    assert code == 70 and "Traceback" in err and "pose_findings" in err


@pytest.mark.parametrize("command", ["certify", "digest", "watch"])
def test_a_fifo_inside_a_bag_folder_is_refused_without_blocking(seeds: dict[tuple[str, bool], Path], tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str],
                                                                command: str) -> None:
    bag = _mcap_folder(seeds["mcap", False], tmp_path / "bag")
    storage = next(bag.glob("*.mcap"))
    storage.unlink()
    os.mkfifo(storage)
    timer = threading.Timer(20.0, lambda: open(storage, "wb").close())  # unblocks a reader that waits (a failure)
    timer.start()
    try:
        start = time.perf_counter()
        code, _, err = run([command, str(bag), "--scenario", "nexus-sml"], capsys)
        assert code == 3 and time.perf_counter() - start < 10, err
        one_line_error(err, str(bag), storage.name, "FIFO")
    finally:
        timer.cancel()


def test_batch_discovery_ends_on_a_folder_with_symlinks_to_itself(seeds: dict[tuple[str, bool], Path],
                                                                  tmp_path: Path) -> None:
    root = tmp_path / "runs"
    root.mkdir()
    shutil.copyfile(seeds["mcap", False], root / "run.mcap")
    (root / "again").symlink_to(root, target_is_directory=True)
    (root / "loop").symlink_to(".", target_is_directory=True)
    got: list[Any] = []
    worker = threading.Thread(target=lambda: got.append(discover_logs([root])), daemon=True)
    worker.start()
    worker.join(20.0)
    assert not worker.is_alive(), "discovery did not finish"
    logs, problems = got[0]
    assert [p.name for p in logs] == ["run.mcap"] and problems == []


def test_a_cut_storage_file_in_a_bag_folder_is_named_and_salvaged(seeds: dict[tuple[str, bool], Path],
                                                                 tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    bag = _mcap_folder(seeds["mcap", True], tmp_path / "bag")
    storage = next(bag.glob("*.mcap"))
    with storage.open("r+b") as fh:
        fh.truncate(storage.stat().st_size * 2 // 3)
    code, _, err = run(["certify", str(bag), "--scenario", "nexus-sml", "--spec", SPEC], capsys)
    assert code == 3
    one_line_error(err, str(bag), f"storage file {storage.name}", "--salvage")
    assert "metadata.yaml" not in err
    bare = tmp_path / "cut.mcap"
    shutil.copyfile(storage, bare)
    folder_code, folder_out, _ = run(["certify", str(bag), "--scenario", "nexus-sml", "--spec", SPEC, "--salvage",
                                      "--json"], capsys)
    bare_code, bare_out, _ = run(["certify", str(bare), "--scenario", "nexus-sml", "--spec", SPEC, "--salvage",
                                  "--json"], capsys)
    assert folder_code == bare_code == 1  # the violating run: its visits before the cut fail
    assert '"partial": true' in folder_out and '"partial": true' in bare_out


def test_an_unindexed_ros1_bag_names_salvage(seeds: dict[tuple[str, bool], Path], tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    src = seeds["bag", False]
    cut = tmp_path / "cut.bag"
    cut.write_bytes(src.read_bytes()[: src.stat().st_size * 2 // 3])
    code, _, err = run(["certify", str(cut), "--scenario", "nexus-sml"], capsys)
    assert code == 3
    one_line_error(err, str(cut), "--salvage")
