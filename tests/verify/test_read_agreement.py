"""The fast indexed readers and the plain readers (``TUBEMPC_FAST_INGEST=0``) read a damaged log alike: the same
messages, or the same refusal, with and without ``--salvage``.

Each test is a damage the fault campaign (``benchmarks/fuzz_certify.py``, family ``bytes``) found read differently
by the two paths; the logs are the campaign's seed logs, damaged at a chosen record.
"""

from __future__ import annotations

import sqlite3
import struct
from pathlib import Path
from typing import Any

import pytest

from tubempc.cli import main
from verify.errors import LogReadError
from verify.ingest.mcaprecords import CHUNK_FIXED, MAGIC, MESSAGE_HEAD, RECORD_HEAD, Op, Scan, scan, walk
from verify.ingest.raw import read_raw

from .support import FUZZ

ROOT = Path(__file__).resolve().parents[2]
POSE, CAMERA = "/qualisys/nexus/pose", "/camera/image_raw"
TOPICS = (POSE, "/nexus/nominal_pose", "/nexus/cmd_vel", "/nexus/mpc_status", "/tubempc/metadata")
SPEC = "G[0,inf) !(obs_1 | obs_2 | obs_3 | obs_4)"


@pytest.fixture(scope="module")
def seeds(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("seeds")
    return {fmt: FUZZ.write_run(FUZZ.base_run(violating=False), FUZZ.seed_path(root, fmt, False), fmt)
            for fmt in ("mcap-cam", "mcap-zstd", "dir", "bag-lz4", "db3")}


def read_on(path: Path, fast: bool, monkeypatch: pytest.MonkeyPatch) -> tuple[Any, ...]:
    """What one path reads (with ``--salvage``): per topic its log times and payloads, whether partial; or the
    refusal's text."""
    monkeypatch.setenv("TUBEMPC_FAST_INGEST", "1" if fast else "0")
    try:
        got = read_raw(path, TOPICS, salvage=True)
    except LogReadError as err:
        return ("refused", str(err))
    return ("read", got.partial, {t: ([int(v) for v in x.log_ns], [bytes(p) for p in x.payloads])
                                  for t, x in sorted(got.topics.items())})


def both(path: Path, monkeypatch: pytest.MonkeyPatch) -> tuple[Any, ...]:
    fast, plain = read_on(path, True, monkeypatch), read_on(path, False, monkeypatch)
    assert fast == plain
    return fast


def top_records(buf: bytes) -> list[tuple[int, int, int]]:
    """(opcode, record start, record end) of every top-level record up to the footer."""
    out = []
    pos = len(MAGIC)
    for op, _content, nxt in walk(buf, pos, len(buf) - len(MAGIC)):
        out.append((op, pos, nxt))
        pos = nxt
        if op == Op.FOOTER:
            break
    return out


def chunk_records(buf: bytes, start: int) -> tuple[int, list[tuple[int, int, bytes]]]:
    """An uncompressed chunk record at ``start`` -> (file position of its records, [(opcode, position in the
    records, content)])."""
    (name_len,) = struct.unpack_from("<I", buf, start + RECORD_HEAD + CHUNK_FIXED)
    assert name_len == 0
    base = start + RECORD_HEAD + CHUNK_FIXED + 4 + 8
    (stored,) = struct.unpack_from("<Q", buf, base - 8)
    inner = buf[base : base + stored]
    out, pos = [], 0
    for op, content, nxt in walk(inner, 0, len(inner)):
        out.append((op, pos, bytes(content)))
        pos = nxt
    return base, out


def channel_ids(buf: bytes) -> dict[str, int]:
    found = Scan({}, {})
    for _ in scan(buf, found):
        pass
    return {ch.topic: cid for cid, ch in found.channels.items()}


def test_a_chunk_length_the_index_contradicts(seeds: dict[str, Path], tmp_path: Path,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """A chunk record whose own length is damaged: the indexed reader went by the chunk index and read everything;
    the scan stops there. Both now salvage the records before it."""
    buf = bytearray(seeds["mcap-zstd"].read_bytes())
    chunks = [(s, e) for op, s, e in top_records(bytes(buf)) if op == Op.CHUNK]
    start = chunks[len(chunks) // 2][0]
    struct.pack_into("<Q", buf, start + 1, 1 << 27)
    path = tmp_path / "damaged.mcap"
    path.write_bytes(bytes(buf))
    got = both(path, monkeypatch)
    assert got[0] == "read" and got[1] is True  # salvaged: partial
    assert 0 < len(got[2][POSE][0]) < 301


def test_an_unwanted_record_cut_inside_a_chunk_read_message_by_message(seeds: dict[str, Path], tmp_path: Path,
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """An uncompressed chunk shared with a camera topic is read message by message (only the wanted records); a
    camera record whose length is damaged stops the scan, so the indexed reader checks the chunk's record chain
    (heads only) and both refuse the file alike."""
    buf = bytearray(seeds["mcap-cam"].read_bytes())
    camera = channel_ids(bytes(buf))[CAMERA]
    chunks = [s for op, s, _e in top_records(bytes(buf)) if op == Op.CHUNK]
    start = chunks[len(chunks) // 2]
    base, inner = chunk_records(bytes(buf), start)
    at = next(pos for op, pos, content in inner
              if op == Op.MESSAGE and struct.unpack_from("<H", content, 0)[0] == camera)
    (length,) = struct.unpack_from("<Q", buf, base + at + 1)
    struct.pack_into("<Q", buf, base + at + 1, length + 3)  # now ends inside the next record
    path = tmp_path / "damaged.mcap"
    path.write_bytes(bytes(buf))
    got = both(path, monkeypatch)
    # a record that runs past the end of its (complete) chunk is damage, not a cut: refused, never salvaged
    assert got[0] == "refused" and "malformed" in got[1] and "runs past its end" in got[1], got


def test_a_malformed_channel_record_inside_a_chunk(seeds: dict[str, Path], tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """A channel record inside a chunk whose topic string runs past its record: the scan stops at it; the
    indexed reader now parses a chunk's schema and channel records too."""
    buf = bytearray(seeds["mcap-cam"].read_bytes())
    for _op, start, _end in (r for r in top_records(bytes(buf)) if r[0] == Op.CHUNK):
        base, inner = chunk_records(bytes(buf), start)
        hits = [pos for op, pos, _c in inner if op == Op.CHANNEL]
        if hits:
            struct.pack_into("<I", buf, base + hits[0] + RECORD_HEAD + 4, 1 << 20)  # the topic's length
            break
    else:
        pytest.skip("no channel record inside a chunk")
    path = tmp_path / "damaged.mcap"
    path.write_bytes(bytes(buf))
    both(path, monkeypatch)


def test_a_message_outside_its_chunks_time_range_is_read_by_both(seeds: dict[str, Path], tmp_path: Path,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """A pose message whose log time lies after its chunk's indexed end time: the indexed reader dropped it (as
    rosbags does) and then refused the file as declaring more messages than it holds; the scan and the format's
    reference reader keep it. Both now read it, at its log time."""
    buf = bytearray(seeds["mcap-cam"].read_bytes())
    pose = channel_ids(bytes(buf))[POSE]
    chunks = [s for op, s, _e in top_records(bytes(buf)) if op == Op.CHUNK]
    base, inner = chunk_records(bytes(buf), chunks[0])
    at = next(pos for op, pos, content in inner
              if op == Op.MESSAGE and struct.unpack_from("<H", content, 0)[0] == pose)
    (log_ns,) = struct.unpack_from("<Q", buf, base + at + RECORD_HEAD + 6)
    moved = log_ns + 3_600 * 10**9
    struct.pack_into("<Q", buf, base + at + RECORD_HEAD + 6, moved)
    assert MESSAGE_HEAD == 22
    path = tmp_path / "damaged.mcap"
    path.write_bytes(bytes(buf))
    got = both(path, monkeypatch)
    assert got[0] == "read" and got[1] is False
    assert got[2][POSE][0][-1] == moved and len(got[2][POSE][0]) == 301


def test_a_sqlite3_row_without_data_is_one_line_on_both_paths(seeds: dict[str, Path], tmp_path: Path,
                                                              monkeypatch: pytest.MonkeyPatch,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    """A damaged sqlite3 page can hold a message row whose columns read as NULL; rosbags yields it with its data
    None, which ended in a TypeError (exit 70)."""
    import shutil

    folder = tmp_path / "bag"
    shutil.copytree(seeds["dir"], folder)
    (db,) = folder.glob("*.db3")
    con = sqlite3.connect(db)
    con.execute("PRAGMA writable_schema=ON")
    con.execute("UPDATE sqlite_master SET sql=replace(sql, 'data BLOB NOT NULL', 'data BLOB') WHERE name='messages'")
    con.commit()
    con.close()
    con = sqlite3.connect(db)
    con.execute("UPDATE messages SET data=NULL WHERE id=(SELECT min(m.id) FROM messages m JOIN topics t "
                "ON m.topic_id=t.id WHERE t.name=?)", (POSE,))
    con.commit()
    con.close()
    for fast in ("1", "0"):
        monkeypatch.setenv("TUBEMPC_FAST_INGEST", fast)
        with pytest.raises(SystemExit) as exc:
            main(["certify", str(folder), "--scenario", "nexus-sml", "--spec", SPEC, "--salvage"])
        err = capsys.readouterr().err.strip()
        assert exc.value.code == 3, err
        assert err.count("\n") == 0 and POSE in err and "damaged sqlite3 log" in err, err
    # the follower reads the row as the readers do
    with pytest.raises(SystemExit) as exc:
        main(["watch", str(folder), "--scenario", "nexus-sml", "--spec", SPEC, "--time-base", "auto"])
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 3 and err.count("\n") == 0 and "damaged sqlite3 log" in err and POSE in err, err


def test_an_unwanted_message_on_an_undeclared_channel(seeds: dict[str, Path], tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """A camera message whose channel id is damaged: the scan refuses a message on a channel the file never
    declares; the indexed reader, reading only the wanted records of that chunk, read on. Both refuse now."""
    buf = bytearray(seeds["mcap-cam"].read_bytes())
    camera = channel_ids(bytes(buf))[CAMERA]
    start = [s for op, s, _e in top_records(bytes(buf)) if op == Op.CHUNK][1]
    base, inner = chunk_records(bytes(buf), start)
    at = next(pos for op, pos, content in inner
              if op == Op.MESSAGE and struct.unpack_from("<H", content, 0)[0] == camera)
    struct.pack_into("<H", buf, base + at + RECORD_HEAD, 999)
    path = tmp_path / "damaged.mcap"
    path.write_bytes(bytes(buf))
    got = both(path, monkeypatch)
    assert got[0] == "refused" and "channel 999" in got[1]


def test_a_summary_channel_that_differs_from_the_data_sections(seeds: dict[str, Path], tmp_path: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """The summary repeats a channel with a damaged topic: the scan takes the channel's first record (in the data
    section), rosbags' summary the damaged copy; the indexed reader now declines and both read the same topics."""
    buf = bytearray(seeds["mcap-zstd"].read_bytes())
    pose = channel_ids(bytes(buf))[POSE]
    records = top_records(bytes(buf))
    chunk_at = [s for op, s, _e in records if op == Op.CHUNK]
    summary = [(s, e) for op, s, e in records if op == Op.CHANNEL and s > chunk_at[-1]]
    for s, _e in summary:
        if struct.unpack_from("<H", buf, s + RECORD_HEAD)[0] == pose:
            (n,) = struct.unpack_from("<I", buf, s + RECORD_HEAD + 4)
            buf[s + RECORD_HEAD + 8 + n - 4 : s + RECORD_HEAD + 8 + n] = b"XXXX"  # the topic's last 4 bytes
            break
    else:
        pytest.skip("the summary does not repeat the channels")
    path = tmp_path / "damaged.mcap"
    path.write_bytes(bytes(buf))
    got = both(path, monkeypatch)
    assert got[0] == "read" and len(got[2][POSE][0]) == 301


def test_a_chunk_whose_size_field_the_index_contradicts(seeds: dict[str, Path], tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """A chunk's uncompressed size field zeroed: the indexed reader took the size from the chunk index and read
    the chunk; the scan refuses it. Both refuse now, with the same line."""
    buf = bytearray(seeds["mcap-cam"].read_bytes())
    start = [s for op, s, _e in top_records(bytes(buf)) if op == Op.CHUNK][2]
    struct.pack_into("<Q", buf, start + RECORD_HEAD + 16, 0)
    path = tmp_path / "damaged.mcap"
    path.write_bytes(bytes(buf))
    got = both(path, monkeypatch)
    assert got[0] == "refused" and "header says 0" in got[1]


def test_a_ros1_chunk_info_without_its_time_fields(seeds: dict[str, Path], tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """A chunk info record whose ``start_time`` field name is damaged: rosbags refuses the index (salvage then
    reads the chunks), the fast reader did not need the field. It refuses the index too now."""
    buf = seeds["bag-lz4"].read_bytes()
    assert buf.count(b"start_time=") > 1
    path = tmp_path / "damaged.bag"
    path.write_bytes(buf.replace(b"start_time=", b"start_tima=", 1))
    got = both(path, monkeypatch)
    assert got[0] == "read" and got[1] is True


def test_a_bare_db3_whose_ordered_read_misses_a_row_is_refused(seeds: dict[str, Path],
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """A damaged timestamp index (``PRAGMA integrity_check``: "row N missing from index timestamp_idx") makes the
    ordered read return fewer rows than the table holds; rosbags' open counts the table and its path refuses the
    log. The fast path skipped that count on a bare .db3; it now counts too. Simulated by a rows query that skips
    one pose row, as the damaged index does."""
    from verify.ingest import sqlite as sqlite_module
    from verify.ingest.sqlite import rosbags_query

    con = sqlite3.connect(f"file:{seeds['db3']}?immutable=1", uri=True)
    (skip,) = con.execute("SELECT min(m.id) FROM messages m JOIN topics t ON m.topic_id=t.id WHERE t.name=?",
                          (POSE,)).fetchone()
    con.close()
    monkeypatch.setattr(sqlite_module, "rosbags_query",
                        lambda ids: rosbags_query(ids).replace("ORDER BY", f"AND messages.id != {int(skip)} ORDER BY"))
    monkeypatch.setenv("TUBEMPC_FAST_INGEST", "1")
    with pytest.raises(LogReadError, match=f"declares 301 messages on {POSE} but only 300"):
        read_raw(seeds["db3"], TOPICS)


@pytest.mark.parametrize("mode", ["file", "message"])
def test_compressed_mcap_folders_are_read_by_the_projects_reader(tmp_path: Path, mode: str,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """ROS 2 MCAP bag folders compressed per file (``name.mcap.zstd``) or per message: both read paths return what
    the format's reference reader (``mcap``) reads from the decompressed storage (payloads decompressed, sorted by
    log time), and the plain path reads them through the project's MCAP scan, not rosbags' storage."""
    import io

    import mcap.reader as mcap_reader
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2
    from rosbags.typesys import Stores, get_typestore

    from verify.ingest import mcapfile
    from verify.ingest.mcaprecords import zstd

    store = get_typestore(Stores.ROS2_HUMBLE)
    string = store.types["std_msgs/msg/String"]
    folder = tmp_path / "bag"
    writer = Writer2(folder, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.set_compression(CompressionMode.FILE if mode == "file" else CompressionMode.MESSAGE,
                           CompressionFormat.ZSTD)
    with writer:
        a = writer.add_connection("/a", "std_msgs/msg/String", typestore=store)
        b = writer.add_connection("/b", "std_msgs/msg/String", typestore=store)
        for k in range(50):  # /b's log times out of order: read back sorted by log time
            writer.write(a, 1_000 + k, bytes(store.serialize_cdr(string(data=f"a{k}"), "std_msgs/msg/String")))
            writer.write(b, 5_000 - k, bytes(store.serialize_cdr(string(data=f"b{k}"), "std_msgs/msg/String")))
    (storage,) = [p for p in folder.iterdir() if p.name != "metadata.yaml"]
    raw = storage.read_bytes()
    if mode == "file":
        raw = zstd.decompress(raw)
    want: dict[str, tuple[list[int], list[bytes]]] = {"/a": ([], []), "/b": ([], [])}
    for _s, channel, message in mcap_reader.make_reader(io.BytesIO(raw)).iter_messages(log_time_order=True):
        data = message.data if mode == "file" else zstd.decompress(message.data)
        want[channel.topic][0].append(message.log_time)
        want[channel.topic][1].append(data)
    used: list[Path] = []
    real = mcapfile._read_scanned
    monkeypatch.setattr(mcapfile, "_read_scanned", lambda f, *a, **k: used.append(f) or real(f, *a, **k))
    for fast in ("1", "0"):
        monkeypatch.setenv("TUBEMPC_FAST_INGEST", fast)
        got = read_raw(folder, ["/a", "/b"])
        assert {t: ([int(v) for v in x.log_ns], [bytes(p) for p in x.payloads]) for t, x in got.topics.items()} == want
    assert used  # the plain path went through the project's scan, not rosbags' storage


@pytest.mark.parametrize(("seed", "cut_b"), [("mcap-zstd", 100), ("bag-lz4", 30)])
def test_a_log_cut_after_its_data_is_partial_for_certify_and_watch(seeds: dict[str, Path], tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str], seed: str,
                                                                    cut_b: int) -> None:
    """An MCAP file cut after its data section (DataEnd) but before its footer, a ROS1 bag cut inside its index
    (after the bag header already points to it): certify reads each as truncated (--salvage: partial); the follower
    took DataEnd, or reaching ``index_pos``, as the recorder's close and passed them. It now waits for the footer, or
    the whole index the bag header announces, as the scan does: both judge them partial (never a pass)."""
    buf = seeds[seed].read_bytes()
    path = tmp_path / f"cut{seeds[seed].suffix}"
    path.write_bytes(buf[: len(buf) - cut_b])
    codes = []
    for argv in (["certify", str(path), "--salvage"], ["watch", str(path), "--time-base", "auto"]):
        with pytest.raises(SystemExit) as exc:
            main([*argv, "--scenario", "nexus-sml", "--spec", SPEC])
        codes.append(exc.value.code)
        capsys.readouterr()
    assert codes == [2, 2]


@pytest.mark.parametrize("fast", ["1", "0"])
def test_a_folder_whose_metadata_names_a_topic_its_storage_lacks_is_damaged_for_certify_and_watch(
        seeds: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
        fast: str) -> None:
    """One flipped bit in a sqlite3 folder's metadata.yaml renamed /nexus/cmd_vel to /nezus/cmd_vel (the fault
    campaign, seed 65 case 37): certify took the folder's topics from metadata.yaml (no cmd_vel: inconclusive, exit
    2), watch the storage's (pass, exit 0). One rule now (``mcapfile.check_declared_topics``): a declared topic with
    messages that the storage does not hold is damage, exit 3 naming both sides, for both read paths and watch."""
    import shutil

    folder = tmp_path / "renamed"
    shutil.copytree(seeds["dir"], folder)
    meta = folder / "metadata.yaml"
    text = meta.read_text(encoding="utf-8")
    assert "/nexus/cmd_vel" in text
    meta.write_text(text.replace("/nexus/cmd_vel", "/nezus/cmd_vel"), encoding="utf-8")
    monkeypatch.setenv("TUBEMPC_FAST_INGEST", fast)
    for command in ("certify", "watch"):
        with pytest.raises(SystemExit) as exc:
            main([command, str(folder), "--scenario", "nexus-sml", "--spec", SPEC])
        err = capsys.readouterr().err
        assert exc.value.code == 3, (command, err)
        assert "metadata.yaml declares" in err and "/nezus/cmd_vel" in err and "/nexus/cmd_vel" in err, err
