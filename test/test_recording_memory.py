"""A long recording's memory stays bounded (issue #25, symptom 2): the recorder's retained Python memory does
not grow with the number of chunks written, and the file it writes is still a complete, indexed MCAP that the
mcap library (seeking reader through the summary's chunk index), rosbags and our reader read in full.

Before the fix the recorder wrote through ``mcap.writer.Writer``, which keeps one ``ChunkIndex`` (with a dict of
one message-index offset per channel) in memory per chunk until ``finish()``: ~45 B per channel per chunk.
"""

from __future__ import annotations

import gc
import struct
import tracemalloc
import zlib

import pytest

pytest.importorskip("mcap")

from bldc_actuator.recording import McapRecorder, read_raw  # noqa: E402

CHANNELS = 50          # a 12-joint node records ~50 topics at 1 kHz
CHUNK = 2048           # small chunks: many chunks from few messages (the growth is per chunk)
PAYLOAD = bytes(range(40))  # opaque bytes: the writer does not decode


def _recorder(path, **kw):
    rec = McapRecorder(path, chunk_size=CHUNK, flush_interval=None, **kw)
    topics = [f"/node/j{k}/q_axis_state" for k in range(CHANNELS)]
    for t in topics:
        rec.add_topic(t, "std_msgs/msg/Float64MultiArray")
    return rec, topics


def _write_periods(rec, topics, start, periods):
    for p in range(start, start + periods):
        t = p * 1_000_000
        for topic in topics:
            rec.write_serialized(topic, PAYLOAD, t)


def _traced() -> int:
    gc.collect()
    return tracemalloc.get_traced_memory()[0]


def test_recorder_memory_does_not_grow_with_chunks(tmp_path):
    path = tmp_path / "long.mcap"
    rec, topics = _recorder(path)
    tracemalloc.start()
    try:
        _write_periods(rec, topics, 0, 200)          # warm up: every channel, dicts at their size
        before = _traced()
        _write_periods(rec, topics, 200, 4000)       # 200k messages
        after = _traced()
    finally:
        tracemalloc.stop()
    rec.close()
    scan = read_raw(path, keep_messages=False)
    n_chunks = scan.statistics.chunk_count
    assert n_chunks > 2000, n_chunks                  # the scenario really wrote thousands of chunks
    growth = after - before
    # bounded: the open chunk and one spill block of the index (64 KiB), not ~45 B x 50 channels x chunks
    # (the old writer: ~2.2 kB per chunk, > 4 MB here)
    assert growth < 160 * 1024, f"recorder memory grew by {growth} B over ~{n_chunks} chunks"


def _records(path):
    from mcap.stream_reader import StreamReader

    with open(path, "rb") as f:
        return list(StreamReader(f, skip_magic=False).records)


def test_file_matches_the_mcap_reference_writer_record_for_record(tmp_path):
    """The same calls through mcap.writer.Writer (the format's reference) give the same records: chunks,
    message indexes, metadata, schemas, channels, statistics, chunk indexes, summary offsets, footer."""
    from mcap.records import Footer, Header
    from mcap.writer import CompressionType, Writer

    from bldc_actuator.recording.mcap_stream import McapStreamWriter

    def drive(w):
        w.start(profile="ros2", library="x")
        s = w.register_schema(name="std_msgs/msg/Float64", encoding="ros2msg", data=b"float64 data")
        ids = [w.register_channel(topic=f"/t{k}", message_encoding="cdr", schema_id=s,
                                  metadata={"offered_qos_profiles": ""}) for k in range(7)]
        for i in range(3000):
            cid = ids[i % 7] if i % 11 else ids[0]
            w.add_message(cid, log_time=10_000 + i * 1000, data=struct.pack("<d", i * 0.5),
                          publish_time=10_000 + i * 1000, sequence=i)
            if i in (5, 1700):
                w.add_metadata("bldc_actuator", {"record": str(i)})
            if i == 2500:
                w.flush()
        w.finish()

    ref, ours = tmp_path / "ref.mcap", tmp_path / "ours.mcap"
    with open(ref, "wb") as f:
        drive(Writer(f, chunk_size=1500, compression=CompressionType.NONE))

    with open(ours, "wb") as f:
        drive(McapStreamWriter(f, chunk_size=1500, compression="", index_dir=tmp_path))
    a, b = _records(ref), _records(ours)
    assert len(a) == len(b) > 100
    for x, y in zip(a, b):
        if isinstance(x, Header):
            continue
        if isinstance(x, Footer):   # the summary CRC covers the footer's own fields too
            assert (x.summary_start, x.summary_offset_start) == (y.summary_start, y.summary_offset_start)
            continue
        assert x == y, type(x).__name__
    assert ref.stat().st_size == ours.stat().st_size


def _summary_crc_ok(path) -> bool:
    data = path.read_bytes()
    footer = data[-8 - 29:-8]
    opcode, length, summary_start, offset_start, crc = struct.unpack("<BQQQI", footer)
    assert opcode == 0x02 and length == 20
    return zlib.crc32(data[summary_start:-8 - 4]) == crc


def test_long_file_is_indexed_and_read_by_every_reader(tmp_path):
    """More chunk index than one spill block (so part of the summary came from the side file): the summary
    has one chunk index per chunk, a valid CRC, and the mcap seeking reader, rosbags and read_raw read every
    message."""
    from mcap.reader import make_reader

    path = tmp_path / "idx.mcap"
    rec, topics = _recorder(path, parameters={"drive.bus_voltage": 24.0})
    _write_periods(rec, topics, 0, 600)
    rec.close()
    n = 600 * CHANNELS
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary.statistics.message_count == n
        assert len(summary.chunk_indexes) == summary.statistics.chunk_count > 300
        # ~600 B per chunk index x > 300 chunks: more than the 64 KiB kept in memory before a spill
        times = [m.log_time for _, _, m in reader.iter_messages(log_time_order=True)]
        assert len(times) == n and times == sorted(times)
        # the index really locates data: a time window read through it
        window = list(reader.iter_messages(starting_at=300 * 1_000_000, ending_before=301 * 1_000_000))
        assert len(window) == CHANNELS
        assert {c.topic for c in summary.channels.values()} == set(topics)
    assert _summary_crc_ok(path)
    scan = read_raw(path)
    assert scan.finalized and not scan.issues
    assert sum(s[0] for s in scan.stats.values()) == n
    rosbags = pytest.importorskip("rosbags.rosbag2")
    with rosbags.Reader(path) as r:
        assert r.message_count == n
        assert sum(1 for _ in r.messages()) == n


def test_no_side_file_is_left_beside_the_recording(tmp_path):
    path = tmp_path / "clean.mcap"
    rec, topics = _recorder(path)
    _write_periods(rec, topics, 0, 300)
    rec.close()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clean.mcap"]


def test_a_full_disk_under_the_side_index_stops_the_recording_cleanly(tmp_path, monkeypatch):
    """The side file shares the recording's disk: when writing the index there fails (ENOSPC) the recording
    stops as for any write error (RecordingWriteError, file cut at a chunk boundary, readable)."""
    import errno

    from bldc_actuator.recording import RecordingWriteError, read_recording
    from bldc_actuator.recording import mcap_stream

    path = tmp_path / "full.mcap"
    rec, topics = _recorder(path)
    _write_periods(rec, topics, 0, 100)

    def full(self):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(mcap_stream.McapStreamWriter, "_spill", full)
    with pytest.raises(RecordingWriteError) as info:
        _write_periods(rec, topics, 100, 1000)
    assert info.value.errno == errno.ENOSPC and rec.closed
    got = read_raw(path, keep_messages=False)
    assert not got.finalized
    n = sum(s[0] for s in got.stats.values())
    assert 100 * CHANNELS <= n < 1100 * CHANNELS
    assert read_recording(path).issues   # says it is not finalized
    assert sorted(p.name for p in tmp_path.iterdir()) == ["full.mcap"]
