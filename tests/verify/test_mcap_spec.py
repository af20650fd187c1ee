"""MCAP files as the specification allows them: both read paths (``TUBEMPC_FAST_INGEST=1`` and ``=0``) return
exactly the messages the format's reference reader (the ``mcap`` package) returns -- topic, log time, payload, in
log-time order -- on every combination its writer offers, and on files written by hand for what it does not offer
(no summary, padded records, unknown records); a file that declares messages that cannot be found is refused."""

from __future__ import annotations

import itertools
import struct
import zlib
from collections.abc import Iterator
from pathlib import Path

import mcap.reader as mcap_reader  # the format's reference reader (the test extra pins it)
import mcap.writer as mcap_writer
import pytest
from rosbags.typesys import Stores, get_typestore

from verify.errors import LogReadError, TruncatedLogError
from verify.ingest.raw import FAST_INGEST_ENV, read_raw

STORE = get_typestore(Stores.ROS2_HUMBLE)
T = STORE.types
TWIST = "geometry_msgs/msg/Twist"
STRING = "std_msgs/msg/String"
TOPICS = ("/cmd", "/status")
MAGIC = b"\x89MCAP0\r\n"
T0 = 1_700_000_000 * 10**9


def _twist(x: float) -> bytes:
    lin = T["geometry_msgs/msg/Vector3"](x=x, y=0.0, z=0.0)
    return bytes(STORE.serialize_cdr(T[TWIST](linear=lin, angular=lin), TWIST))


def _string(text: str) -> bytes:
    return bytes(STORE.serialize_cdr(T[STRING](data=text), STRING))


def _messages() -> list[tuple[str, int, bytes]]:
    """60 messages on two topics, log times out of order within and across chunks, with ties."""
    out = []
    for i in range(60):
        t = T0 + ((i * 37) % 23) * 10_000_000  # a permutation with repeats: out of order, ties
        out.append(("/cmd", t, _twist(float(i))) if i % 3 else ("/status", t, _string("s" * (i % 5))))
    return out


def _oracle(path: Path) -> dict[str, list[tuple[int, bytes]]]:
    """What the reference reader returns, per topic, in log-time order."""
    got: dict[str, list[tuple[int, bytes]]] = {}
    with path.open("rb") as fh:
        try:
            rows = [(c.topic, m.log_time, bytes(m.data))
                    for _s, c, m in mcap_reader.make_reader(fh).iter_messages(log_time_order=True)]
        except (KeyError, mcap_reader.McapError):
            # the seeking reader needs every channel in the summary; the stream reader finds them anywhere
            fh.seek(0)
            rows = [(c.topic, m.log_time, bytes(m.data))
                    for _s, c, m in mcap_reader.NonSeekingReader(fh).iter_messages(log_time_order=True)]
    for topic, t, data in rows:
        got.setdefault(topic, []).append((t, data))
    return got


def _ours(path: Path, monkeypatch: pytest.MonkeyPatch, fast: bool) -> dict[str, list[tuple[int, bytes]]]:
    with monkeypatch.context() as m:
        m.setenv(FAST_INGEST_ENV, "1" if fast else "0")
        raw = read_raw(path, TOPICS)
    assert raw.available == {"/cmd": TWIST, "/status": STRING}
    out = {}
    for topic, t in raw.topics.items():
        assert t.msgtype == raw.available[topic] and t.has_definition
        out[topic] = list(zip((int(x) for x in t.log_ns), list(t.payloads), strict=True))
    return out


def _writer_file(path: Path, **options: object) -> Path:
    with path.open("wb") as fh:
        w = mcap_writer.Writer(fh, **options)
        w.start(profile="ros2", library="test")
        defs = {TWIST: "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n", STRING: "string data\n"}
        sids = {name: w.register_schema(name=name, encoding="ros2msg", data=text.encode())
                for name, text in defs.items()}
        cids = {"/cmd": w.register_channel("/cmd", "cdr", sids[TWIST]),
                "/status": w.register_channel("/status", "cdr", sids[STRING])}
        w.add_metadata("run", {"robot": "nexus"})
        for k, (topic, t, data) in enumerate(_messages()):
            w.add_message(cids[topic], log_time=t, data=data, publish_time=t, sequence=k)
            if k == 30:
                w.add_attachment(T0, T0, "calib.txt", "text/plain", b"k=1")
        w.finish()
    return path


def _writer_combinations() -> Iterator[dict[str, object]]:
    it = mcap_writer.IndexType
    for chunking, index, stats, offsets, rep_ch, rep_sc, comp in itertools.product(
            (True, False), (it.ALL, it.CHUNK, it.MESSAGE, it.NONE), (True, False), (True, False), (True, False),
            (True, False), tuple(mcap_writer.CompressionType)):
        if not chunking and comp != mcap_writer.CompressionType.NONE:
            continue  # compression applies to chunks only
        yield {"use_chunking": chunking, "index_types": index, "use_statistics": stats,
               "use_summary_offsets": offsets, "repeat_channels": rep_ch, "repeat_schemas": rep_sc,
               "compression": comp, "chunk_size": 400}


def test_every_writer_combination_reads_as_the_reference_reader(tmp_path: Path,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    combos = list(_writer_combinations())
    assert len(combos) == 256
    order = sorted(((t, k) for k, (_tp, t, _d) in enumerate(_messages())))
    assert order != [(t, k) for k, (_tp, t, _d) in enumerate(_messages())]  # the input is out of log-time order
    bad = []
    for k, options in enumerate(combos):
        path = _writer_file(tmp_path / f"w{k}.mcap", **options)
        want = _oracle(path)
        assert sum(len(v) for v in want.values()) == 60
        for fast in (True, False):
            got = _ours(path, monkeypatch, fast)
            if got != want:
                bad.append((options, fast))
    assert not bad, bad[:3]


# ---- files written by hand -------------------------------------------------------------------------------------
def _rec(op: int, content: bytes) -> bytes:
    return bytes([op]) + struct.pack("<Q", len(content)) + content


def _s(text: str) -> bytes:
    b = text.encode()
    return struct.pack("<I", len(b)) + b


def _schema(sid: int, name: str, pad: bytes = b"") -> bytes:
    data = b"# definition\n"
    return _rec(0x03, struct.pack("<H", sid) + _s(name) + _s("ros2msg") + struct.pack("<I", len(data)) + data + pad)


def _channel(cid: int, sid: int, topic: str, pad: bytes = b"") -> bytes:
    return _rec(0x04, struct.pack("<HH", cid, sid) + _s(topic) + _s("cdr") + struct.pack("<I", 0) + pad)


def _message(cid: int, t: int, data: bytes) -> bytes:
    return _rec(0x05, struct.pack("<HIQQ", cid, 0, t, t) + data)


def _chunk(records: bytes, pad: bytes = b"") -> bytes:
    head = struct.pack("<QQQI", 0, 0, len(records), zlib.crc32(records)) + _s("")
    return _rec(0x06, head + struct.pack("<Q", len(records)) + records + pad)


def _file(body: bytes) -> bytes:
    header = _rec(0x01, _s("ros2") + _s("hand"))
    data_end = _rec(0x0F, struct.pack("<I", 0))
    footer = _rec(0x02, struct.pack("<QQI", 0, 0, 0))  # no summary
    return MAGIC + header + body + data_end + footer + MAGIC


def _hand_files() -> dict[str, tuple[bytes, dict[str, list[tuple[int, bytes]]]]]:
    """name -> (file bytes, the messages it holds per topic in log-time order)."""
    msgs = _messages()
    ids = {"/cmd": 1, "/status": 2}
    defs = _schema(1, TWIST) + _schema(2, STRING) + _channel(1, 1, "/cmd") + _channel(2, 2, "/status")
    padded_defs = (_schema(1, TWIST, b"\x00" * 7) + _schema(2, STRING, b"future") + _channel(1, 1, "/cmd", b"\x01" * 5)
                   + _channel(2, 2, "/status", b"\x00" * 3))
    loose = b"".join(_message(ids[tp], t, d) for tp, t, d in msgs)
    halves = [b"".join(_message(ids[tp], t, d) for tp, t, d in part) for part in (msgs[:25], msgs[25:])]
    unknown = _rec(0x80, b"a record of a later version") + _rec(0x0C, _s("meta") + struct.pack("<I", 0))
    want: dict[str, list[tuple[int, bytes]]] = {}
    for tp, t, d in sorted(msgs, key=lambda m: m[1]):
        want.setdefault(tp, []).append((t, d))
    return {
        "no_summary_unchunked": (_file(defs + loose), want),
        "no_summary_chunked": (_file(defs + _chunk(halves[0]) + _chunk(halves[1])), want),
        "channels_in_chunks": (_file(_chunk(defs + halves[0]) + _chunk(halves[1])), want),
        "padded_records": (_file(padded_defs + unknown + loose), want),
        "padded_in_chunks": (_file(_chunk(padded_defs + halves[0], b"pad") + unknown + _chunk(halves[1])), want),
    }


@pytest.mark.parametrize("name", sorted(_hand_files()))
def test_hand_written_files(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, name: str) -> None:
    data, want = _hand_files()[name]
    path = tmp_path / f"{name}.mcap"
    path.write_bytes(data)
    if "in_chunks" not in name:  # the reference reader does not skip padding inside chunks
        assert _oracle(path) == want
    for fast in (True, False):
        assert _ours(path, monkeypatch, fast) == want, fast


def test_declared_messages_that_cannot_be_found_are_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The statistics declare messages on /cmd that the file does not hold: refused naming the topic, both ways,
    never an empty or short topic."""
    src = _writer_file(tmp_path / "w.mcap", use_chunking=False, index_types=mcap_writer.IndexType.NONE)
    data = src.read_bytes()
    with src.open("rb") as fh:
        summary = mcap_reader.make_reader(fh).get_summary()
    assert summary is not None and summary.statistics is not None
    cmd_id = next(c.id for c in summary.channels.values() if c.topic == "/cmd")
    have = summary.statistics.channel_message_counts[cmd_id]
    pair = struct.pack("<HQ", cmd_id, have)
    assert data.count(pair) == 1
    path = tmp_path / "more.mcap"
    path.write_bytes(data.replace(pair, struct.pack("<HQ", cmd_id, have + 5)))
    for fast in ("1", "0"):
        monkeypatch.setenv(FAST_INGEST_ENV, fast)
        with pytest.raises(TruncatedLogError, match=f"declares {have + 5} messages on /cmd but only {have}"):
            read_raw(path, TOPICS)


def test_a_channel_without_its_schema_and_a_message_without_its_channel(tmp_path: Path,
                                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "noschema.mcap"
    path.write_bytes(_file(_channel(1, 9, "/cmd") + _message(1, T0, _twist(1.0))))
    path2 = tmp_path / "nochannel.mcap"
    path2.write_bytes(_file(_schema(1, TWIST) + _message(4, T0, _twist(1.0))))
    for fast in ("1", "0"):
        monkeypatch.setenv(FAST_INGEST_ENV, fast)
        with pytest.raises(LogReadError, match=r"channel 1 \(/cmd\) has no schema record"):
            read_raw(path, TOPICS)
        with pytest.raises(LogReadError, match="refers to channel 4, which the file never declares"):
            read_raw(path2, TOPICS)


def test_a_cut_file_is_truncated_and_salvages(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    data = _hand_files()["no_summary_unchunked"][0]
    path = tmp_path / "cut.mcap"
    path.write_bytes(data[: len(data) * 2 // 3])
    for fast in ("1", "0"):
        monkeypatch.setenv(FAST_INGEST_ENV, fast)
        with pytest.raises(TruncatedLogError, match="--salvage"):
            read_raw(path, TOPICS)
        got = read_raw(path, TOPICS, salvage=True)
        assert got.partial and 0 < len(got.topics["/cmd"].payloads) < 40
