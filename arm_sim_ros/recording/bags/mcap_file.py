"""MCAP storage for rosbag2 bags that opens at every moment: rosbags' MCAP writer, with
each chunk written as it closes together with a complete end of file.

A kill -9 of the recording then loses only the chunk being filled in memory (at most
CHUNK_SECONDS of messages, or about CHUNK_BYTES); a write the disk refuses (a full disk,
a file-size limit) leaves the file as it was before that write: closed and whole.
"""
from __future__ import annotations

import errno
import os
import time
from collections import defaultdict
from contextlib import suppress
from io import BytesIO
from struct import unpack_from

from rosbags.rosbag2.storage_mcap import (McapWriter, PendingChunk, write_channel, write_record,
                                          write_schema, write_string, write_uint16, write_uint32,
                                          write_uint64)

CHUNK_BYTES = 1 << 20    # a chunk goes to disk once it holds this much (rosbags' own size) ...
CHUNK_SECONDS = 1.0      # ... or once its first record has waited this long (wall time)
MAGIC = b"\x89MCAP0\r\n"
MAXTIME = 2**63 - 1      # rosbags' "no message yet" start time


class _Placed(BytesIO):
    """A buffer whose tell() is a file offset: its bytes go to the file at `base`."""

    def __init__(self, base: int):
        super().__init__()
        self.base = base

    def tell(self) -> int:
        return self.base + super().tell()


class DurableMcap(McapWriter):
    """rosbags' MCAP storage, kept a complete MCAP file on disk at every moment.

    Each chunk is written when it closes, together with a new end of file (the rosbag2
    metadata record, data end, a summary indexing every chunk, footer and magic), in one
    write at the end of the data that replaces the previous end. A kill -9 thus loses only
    the chunk being filled in memory. A write the disk refuses (ENOSPC, EFBIG) puts the
    previous end back; the chunk is then written in ever smaller parts while they fit, and
    the error raised: the file holds every message that fit, in order, and stays whole.
    """

    def __init__(self, path, compression):
        super().__init__(path, compression)
        self.bio.flush()                  # the header; from here on only os.pwrite
        self.data_end = self.bio.tell()   # where the next chunk goes
        self.tail = b""                   # the end of file now on disk after data_end
        self.index = bytearray()          # chunk index records of the chunks on disk
        self.metadata_text = ""           # rosbag2's serialized_metadata, as last saved
        self.first_record = None          # monotonic time the pending chunk began
        self.on_disk = {}                 # channel id -> messages in the file
        self.span = (MAXTIME, 0)          # first and last message time in the file
        self.puts = 0                     # successful writes, for the metadata to follow
        self.put(b"")

    def add_msgtype(self, connection) -> None:
        self._begin()
        super().add_msgtype(connection)

    def add_connection(self, connection, offered_qos_profiles) -> None:
        self._begin()
        super().add_connection(connection, offered_qos_profiles)

    def write(self, connection, timestamp, data) -> None:
        self._begin()
        super().write(connection, timestamp, data)

    def _begin(self) -> None:
        if self.first_record is None:
            self.first_record = time.monotonic()

    def due(self) -> bool:
        """Whether the pending chunk should go to disk: it has waited CHUNK_SECONDS, or it
        holds CHUNK_BYTES (more once the index is large, so that rewriting the summary with
        each chunk stays a small part of the work)."""
        size = self.chunk.bio.tell()
        return size > 0 and (size >= max(CHUNK_BYTES, 8 * len(self.index)) or
                             time.monotonic() - self.first_record >= CHUNK_SECONDS)

    def close_chunk(self, force: bool = False) -> None:
        """Write the pending chunk if it is due or `force`d (rosbags calls this past 1 MiB)."""
        if not (self.chunk.bio.tell() and (force or self.due())):
            return
        chunk, self.chunk = self.chunk, _pending()
        self.first_record = None
        try:
            self._write(chunk)
        except OSError:
            self._write_what_fits(chunk)
            raise

    def _write(self, chunk) -> None:
        """One chunk record and its message indexes, through rosbags' own close_chunk."""
        pending, self.chunk = self.chunk, chunk
        real, self.bio = self.bio, _Placed(self.data_end)
        try:
            super().close_chunk()
            body = self.bio.getvalue()
        finally:
            self.bio, self.chunk = real, pending
        entry = BytesIO()
        write_record(entry, 0x08, self.chunks[-1])
        try:
            self.put(body, entry.getvalue(), {c: len(m) for c, m in chunk.msgs.items()},
                     (chunk.message_start_time, chunk.message_end_time))
        except OSError:
            self.chunks.pop()
            raise

    def _write_what_fits(self, chunk) -> None:
        """After a refused write: the chunk's records in halves, quarters... in order,
        until a single message does not fit."""
        parts = [list(_records(chunk.bio.getvalue()))]
        while parts:
            part = parts.pop(0)
            try:
                self._write(_pending(part))
            except OSError:
                messages = [i for i, (op, _) in enumerate(part) if op == 0x05]
                if len(messages) <= 1:
                    return
                half = messages[len(messages) // 2]
                parts[:0] = [part[:half], part[half:]]

    def put(self, body: bytes, index_entry: bytes = b"", counts=None, span=None) -> None:
        """`body` (holding `counts` messages per channel, in the time `span`) at the data
        end, then a new end of file, in one write; on failure the previous end of file is
        put back (its place is allocated already)."""
        on_disk = dict(self.on_disk)
        for cid, n in (counts or {}).items():
            on_disk[cid] = on_disk.get(cid, 0) + n
        if span:
            span = (min(self.span[0], span[0]), max(self.span[1], span[1]))
        span = span or self.span
        tail = self.end_of_file(self.data_end + len(body), self.index + index_entry, on_disk, span)
        data, fd, done = memoryview(body + tail), self.bio.fileno(), 0
        try:
            while done < len(data):
                written = os.pwrite(fd, data[done:], self.data_end + done)
                if written <= 0:
                    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
                done += written
        except OSError:
            with suppress(OSError):
                os.pwrite(fd, self.tail, self.data_end)
                os.ftruncate(fd, self.data_end + len(self.tail))
            raise
        self.data_end += len(body)
        self.tail = tail
        self.index += index_entry
        self.on_disk, self.span = on_disk, span
        self.puts += 1

    def end_of_file(self, at: int, index: bytes, counts: dict, span: tuple) -> bytes:
        """What rosbags' close() writes after the last chunk, for the chunks in `index`
        holding `counts` messages per channel in the time `span`."""
        out = _Placed(at)
        rec, sub = BytesIO(), BytesIO()
        write_string(rec, "rosbag2")
        write_string(sub, "serialized_metadata")
        write_string(sub, self.metadata_text)
        write_uint32(rec, sub.tell())
        rec.write(sub.getbuffer())
        metadata_start = out.tell()
        write_record(out, 0x0C, rec)
        metadata_end = out.tell()
        write_record(out, 0x0F, _record(write_uint32, 0))          # data end, no CRC
        schemas = out.tell()
        for schema in self.schemas:
            write_schema(out, schema)
        channels = out.tell()
        for channel in self.channels:
            write_channel(out, channel, self.schemas)
        chunks = out.tell()
        out.write(index)
        metadata_index = out.tell()
        rec = _record(write_uint64, metadata_start, metadata_end - metadata_start)
        write_string(rec, "rosbag2")
        write_record(out, 0x0D, rec)
        statistics = out.tell()
        count = sum(counts.values())
        rec = _record(write_uint64, count)
        write_uint16(rec, len(self.schemas))
        for value in (len(self.channels), 0, 1, len(self.chunks)):   # attachments, metadata
            write_uint32(rec, value)
        for value in (span if count else (0, 0)):
            write_uint64(rec, value)
        write_uint32(rec, len(counts) * 10)
        for cid, n in sorted(counts.items()):
            write_uint16(rec, cid)
            write_uint64(rec, n)
        write_record(out, 0x0B, rec)
        offsets = out.tell()
        for op, start, end in ((0x03, schemas, channels), (0x04, channels, chunks),
                               (0x08, chunks, metadata_index), (0x0D, metadata_index, statistics),
                               (0x0B, statistics, offsets)):
            if end > start:
                rec = BytesIO(bytes([op]))
                rec.seek(1)
                write_uint64(rec, start)
                write_uint64(rec, end - start)
                write_record(out, 0x0E, rec)
        rec = _record(write_uint64, schemas, offsets)
        write_uint32(rec, 0)
        write_record(out, 0x02, rec)
        out.write(MAGIC)
        return out.getvalue()


def _record(write, *values) -> BytesIO:
    rec = BytesIO()
    for value in values:
        write(rec, value)
    return rec


def _pending(records=()) -> PendingChunk:
    """A chunk holding `records` (op, whole record bytes), indexed as rosbags indexes one."""
    chunk = PendingChunk(MAXTIME, 0, BytesIO(), defaultdict(list))
    for op, record in records:
        if op == 0x05:   # message: channel id, sequence, log time, publish time, data
            cid, _, log_time = unpack_from("<HIQ", record, 9)
            chunk.msgs[cid].append((log_time, chunk.bio.tell()))
            chunk.message_start_time = min(chunk.message_start_time, log_time)
            chunk.message_end_time = max(chunk.message_end_time, log_time)
        chunk.bio.write(record)
    return chunk


def _records(data: bytes):
    """(op, whole record) for each record in an uncompressed chunk's data."""
    at = 0
    while at < len(data):
        (length,) = unpack_from("<Q", data, at + 1)
        yield data[at], data[at:at + 9 + length]
        at += 9 + length
