"""A chunked MCAP writer whose memory does not grow with the recording: the summary's chunk index waits on disk.

Why not ``mcap.writer.Writer``: it keeps one ``ChunkIndex`` object per written chunk in a Python list for the
summary section (with a dict of one offset per channel in the chunk: ~45 B per channel per chunk), whatever
``index_types`` says (the list is appended to unconditionally). A 12-joint node recording at 1 kHz closes ~20
chunks per second, so the writer grew by ~10-20 kB/s, ~40-80 MB per hour, without bound. rosbag2's MCAP storage
plugin (the C++ ``McapWriter``) holds its chunk indexes in memory the same way and bounds them only by splitting
the bag into files (``max_bagfile_size`` / ``max_bagfile_duration``); splitting would change what a recording
is (one file) for every reader here, so this writer keeps one file and moves the index out of memory instead.

:class:`McapStreamWriter` writes the same file as ``mcap.writer.Writer`` with its defaults (chunks with their
message indexes after each one, schemas and channels inside the chunks and repeated in the summary,
statistics, chunk and metadata indexes, summary offsets, summary CRC): what it keeps in memory is bounded by
the open chunk, the schemas and channels, the per-channel message counts and one index entry per metadata
record. Each closed chunk's Chunk Index record is serialised at once and appended to an anonymous temporary
file beside the recording (``tempfile.TemporaryFile``: nothing is left behind by a crash, and it is on the
recording's disk); :meth:`finish` copies those records into the summary in blocks, computing the summary CRC
as it goes. The records themselves are built with ``mcap.records`` (the format's reference layouts); only the
Message record, written 10^4-10^5 times a second, is packed here (opcode 0x05: channel id u16, sequence u32,
log time u64, publish time u64, data).

An unfinalized file (a crash) is exactly what the mcap writer would have left: the complete chunks and their
message indexes; the sidecar index only matters for the summary written by :meth:`finish`.
"""

from __future__ import annotations

import struct
import sys
import tempfile
import zlib
from array import array
from pathlib import Path
from typing import Any, Callable

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, MessageIndex, Metadata,
                          MetadataIndex, Schema, Statistics, SummaryOffset)

MCAP_MAGIC = b"\x89MCAP0\r\n"
_MESSAGE_HEAD = struct.Struct("<BQHIQQ")   # opcode, record length, channel id, sequence, log time, publish time
_MESSAGE_FIELDS = 2 + 4 + 8 + 8
_INDEX_HEAD = struct.Struct("<BQHI")       # opcode, record length, channel id, byte length of the entries
_COPY_BLOCK = 1 << 20                      # bytes per read when the sidecar index goes into the summary
_SPILL_BLOCK = 64 * 1024                   # chunk index bytes buffered before they go to the sidecar
_LITTLE = sys.byteorder == "little"


def _compressor(compression: str) -> Callable[[bytes], bytes] | None:
    if compression == "zstd":
        import zstandard

        return zstandard.ZstdCompressor().compress
    if compression == "lz4":
        import lz4.frame

        return lz4.frame.compress
    if compression == "":
        return None
    raise ValueError(f"compression: expected one of zstd, lz4, '' (none), got {compression!r}")


def _record(rec) -> bytes:
    b = RecordBuilder()
    rec.write(b)
    return b.end()


class McapStreamWriter:
    """Writes a chunked MCAP stream to ``output`` (an object with ``write(bytes)`` and ``tell()``).

    ``chunk_size``: a chunk closes once its uncompressed records exceed this [bytes]; ``compression``:
    ``"zstd"``, ``"lz4"`` or ``""``; ``index_dir``: where the anonymous chunk-index file is created (the
    recording's directory, so it shares its disk; default: the system's temporary directory).
    """

    def __init__(self, output: Any, *, chunk_size: int = 1024 * 1024, compression: str = "zstd",
                 index_dir: str | Path | None = None):
        self._out = output
        self._chunk_size = int(chunk_size)
        self._compression = compression
        self._compress = _compressor(compression)
        self._index_dir = None if index_dir is None else str(index_dir)
        self._schemas: dict[int, Schema] = {}
        self._channels: dict[int, Channel] = {}
        self._metadata_indexes: list[MetadataIndex] = []
        self._counts: dict[int, int] = {}        # messages per channel (the Statistics record)
        self._message_count = 0
        self._metadata_count = 0
        self._chunk_count = 0
        self._start_time = 0
        self._end_time = 0
        # the open chunk
        self._buf = bytearray()
        self._chunk_messages = 0
        self._chunk_start = 0
        self._chunk_end = 0
        self._msg_index: dict[int, array] = {}   # channel id -> [log_time, offset, log_time, offset, ...]
        # chunk indexes: the last few in memory, the rest in the sidecar file
        self._index_pending = bytearray()
        self._index_file = None
        self._index_bytes = 0
        self._finished = False

    # -- sizes (for tests and the recorder) ---------------------------------------------------------
    @property
    def chunk_count(self) -> int:
        return self._chunk_count

    @property
    def open_chunk_bytes(self) -> int:
        return len(self._buf)

    @property
    def retained_index_bytes(self) -> int:
        """Chunk index bytes held in memory (bounded by the spill block)."""
        return len(self._index_pending)

    @property
    def index_bytes(self) -> int:
        """Chunk index bytes written so far (memory and sidecar): the summary's chunk index group."""
        return self._index_bytes

    # -- the mcap.writer.Writer calls the recorder uses ----------------------------------------------
    def start(self, profile: str = "", library: str = "") -> None:
        self._out.write(MCAP_MAGIC + _record(Header(profile=profile, library=library)))

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        schema_id = len(self._schemas) + 1
        schema = Schema(id=schema_id, name=name, encoding=encoding, data=data)
        self._schemas[schema_id] = schema
        self._buf += _record(schema)
        self._maybe_close_chunk()
        return schema_id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int,
                         metadata: dict[str, str] | None = None) -> int:
        channel_id = len(self._channels) + 1
        if channel_id > 0xFFFF:
            raise ValueError(f"topic {topic!r}: MCAP channel ids are 16 bit, at most 65535 channels")
        channel = Channel(id=channel_id, topic=topic, message_encoding=message_encoding, schema_id=schema_id,
                          metadata=dict(metadata or {}))
        self._channels[channel_id] = channel
        self._counts[channel_id] = 0
        self._buf += _record(channel)
        self._maybe_close_chunk()
        return channel_id

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int,
                    sequence: int = 0) -> None:
        buf = self._buf
        index = self._msg_index.get(channel_id)
        if index is None:
            if channel_id not in self._channels:
                raise ValueError(f"channel_id: {channel_id} is not a registered channel")
            index = self._msg_index[channel_id] = array("Q")
        index.append(log_time)
        index.append(len(buf))
        buf += _MESSAGE_HEAD.pack(Opcode.MESSAGE, _MESSAGE_FIELDS + len(data), channel_id, sequence & 0xFFFFFFFF,
                                  log_time, publish_time)
        buf += data
        if self._chunk_messages:
            if log_time < self._chunk_start:
                self._chunk_start = log_time
            if log_time > self._chunk_end:
                self._chunk_end = log_time
        else:
            self._chunk_start = self._chunk_end = log_time
        self._chunk_messages += 1
        self._counts[channel_id] += 1
        if self._message_count:
            if log_time < self._start_time:
                self._start_time = log_time
            if log_time > self._end_time:
                self._end_time = log_time
        else:
            self._start_time = self._end_time = log_time
        self._message_count += 1
        if len(buf) > self._chunk_size:
            self._close_chunk()

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """A Metadata record between chunks (the open chunk, if any, stays open)."""
        record = _record(Metadata(name=name, metadata=data))
        offset = self._out.tell()
        self._out.write(record)
        self._metadata_count += 1
        self._metadata_indexes.append(MetadataIndex(offset=offset, length=len(record), name=name))

    def flush(self) -> None:
        """Close the open chunk now (a chunk without messages is not written)."""
        self._close_chunk()

    # -- chunks -------------------------------------------------------------------------------------
    def _maybe_close_chunk(self) -> None:
        if len(self._buf) > self._chunk_size:
            self._close_chunk()

    def _close_chunk(self) -> None:
        if not self._chunk_messages:
            return
        raw = bytes(self._buf)
        packed = self._compress(raw) if self._compress is not None else raw
        chunk = _record(Chunk(compression=self._compression, data=packed, message_start_time=self._chunk_start,
                              message_end_time=self._chunk_end, uncompressed_crc=zlib.crc32(raw),
                              uncompressed_size=len(raw)))
        chunk_offset = self._out.tell()
        indexes = bytearray()
        offsets: dict[int, int] = {}
        index_start = chunk_offset + len(chunk)
        for channel_id, entries in self._msg_index.items():
            offsets[channel_id] = index_start + len(indexes)
            if not _LITTLE:
                entries.byteswap()
            body = entries.tobytes()
            indexes += _INDEX_HEAD.pack(Opcode.MESSAGE_INDEX, 2 + 4 + len(body), channel_id, len(body))
            indexes += body
        self._out.write(chunk + indexes)   # one write: the chunk and its indexes reach the OS together
        record = _record(ChunkIndex(message_start_time=self._chunk_start, message_end_time=self._chunk_end,
                                    chunk_start_offset=chunk_offset, chunk_length=len(chunk),
                                    message_index_offsets=offsets, message_index_length=len(indexes),
                                    compression=self._compression, compressed_size=len(packed),
                                    uncompressed_size=len(raw)))
        self._chunk_count += 1
        self._buf = bytearray()
        self._msg_index = {}
        self._chunk_messages = 0
        self._index_pending += record
        self._index_bytes += len(record)
        if len(self._index_pending) >= _SPILL_BLOCK:
            self._spill()

    def _spill(self) -> None:
        if self._index_file is None:
            self._index_file = tempfile.TemporaryFile(prefix=".mcap-chunk-index-", dir=self._index_dir)
        self._index_file.write(self._index_pending)
        self._index_pending = bytearray()

    def _chunk_index_blocks(self):
        """The chunk index records in file order, in blocks of at most ~1 MB."""
        if self._index_file is not None:
            f = self._index_file
            f.flush()
            f.seek(0)
            while True:
                block = f.read(_COPY_BLOCK)
                if not block:
                    break
                yield block
        if self._index_pending:
            yield bytes(self._index_pending)

    # -- the end ------------------------------------------------------------------------------------
    def finish(self) -> None:
        """Close the open chunk, write Data End, the summary and the footer. Does not close ``output``."""
        if self._finished:
            return
        self._close_chunk()
        out = self._out
        out.write(_record(DataEnd(data_section_crc=0)))
        summary_start = out.tell()
        crc = 0
        size = 0
        offsets: list[SummaryOffset] = []

        def group(opcode: Opcode, blocks) -> None:
            nonlocal crc, size
            start = size
            for block in blocks:
                out.write(block)
                crc = zlib.crc32(block, crc)
                size += len(block)
            offsets.append(SummaryOffset(group_opcode=opcode, group_start=summary_start + start,
                                         group_length=size - start))

        group(Opcode.SCHEMA, (_record(s) for s in self._schemas.values()))
        group(Opcode.CHANNEL, (_record(c) for c in self._channels.values()))
        group(Opcode.STATISTICS, [_record(Statistics(
            message_count=self._message_count, schema_count=len(self._schemas),
            channel_count=len(self._channels), attachment_count=0, metadata_count=self._metadata_count,
            chunk_count=self._chunk_count, message_start_time=self._start_time, message_end_time=self._end_time,
            channel_message_counts={k: n for k, n in self._counts.items() if n}))])
        group(Opcode.CHUNK_INDEX, self._chunk_index_blocks())
        group(Opcode.ATTACHMENT_INDEX, [])
        group(Opcode.METADATA_INDEX, (_record(m) for m in self._metadata_indexes))
        summary_offset_start = summary_start + size
        tail = b"".join(_record(o) for o in offsets)
        crc = zlib.crc32(tail, crc)
        size += len(tail)
        crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 8 + 8 + 4, summary_start, summary_offset_start), crc)
        footer = _record(Footer(summary_start=summary_start, summary_offset_start=summary_offset_start,
                                summary_crc=crc))
        out.write(tail + footer + MCAP_MAGIC)
        self._finished = True
        self.close_index()

    def close_index(self) -> None:
        """Drop the sidecar index file (after :meth:`finish`, or when the recording is abandoned)."""
        f, self._index_file = self._index_file, None
        if f is not None:
            f.close()
