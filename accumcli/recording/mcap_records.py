"""The MCAP record layer of the reader: records parsed from the file's bytes with every declared
length checked against what the file or the chunk holds.

Why not the mcap library's reader: it trusts declared lengths (a one-byte change of a good file
asks it for gigabytes or raises deep inside), stops at the first damaged chunk, and cannot read a
file without its footer (a recorder that was killed). The record layout (MCAP spec: opcode,
length, fields; chunks with CRC and zstd/lz4 compression) is small and stable, so accum reads it
itself and survives all three (``reader``'s docstring lists what it does then). Writing stays with
the mcap library (``writer``).
"""

from __future__ import annotations

import io
import logging
import os
import struct
import zlib
from dataclasses import dataclass
from typing import Callable, Iterator

import lz4.frame
import zstandard

log = logging.getLogger("accumcli")

MCAP_MAGIC = b"\x89MCAP0\r\n"
MAX_CHUNK_BYTES = 1 << 28   # uncompressed bytes of one chunk (256 MiB)
MAX_RECORD_BYTES = MAX_CHUNK_BYTES + 4096  # bytes of one record that is read (longer ones are skipped)

_OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK = 0x02, 0x03, 0x04, 0x05, 0x06


class _Malformed(ValueError):
    """A record whose fields do not fit its bytes."""


class _Fields:
    """Little-endian MCAP field reader over one record's bytes, bounds-checked."""

    def __init__(self, data: memoryview):
        self.data, self.pos = data, 0

    def take(self, n: int) -> memoryview:
        if n < 0 or self.pos + n > len(self.data):
            raise _Malformed(f"a field of {n} bytes runs past the record's {len(self.data)} bytes")
        out = self.data[self.pos:self.pos + n]
        self.pos += n
        return out

    def int(self, size: int) -> int:
        return int.from_bytes(self.take(size), "little")

    def string(self) -> str:
        return bytes(self.take(self.int(4))).decode("utf-8")

    def rest(self) -> memoryview:
        return self.take(len(self.data) - self.pos)


@dataclass
class _Channel:
    id: int
    schema_name: str
    topic: str
    message_encoding: str
    schema_id: int = 0
    schema_encoding: str = ""
    schema_data: bytes = b""


@dataclass
class _Message:
    channel_id: int
    log_time: int
    data: memoryview


def _records(data: memoryview) -> Iterator[tuple[int, int, memoryview]]:
    """(offset, opcode, content) of the records in ``data``; raises _Malformed."""
    pos, n = 0, len(data)
    while pos < n:
        if pos + 9 > n:
            raise _Malformed(f"a record header at byte {pos} is cut off")
        opcode = data[pos]
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        if length > n - pos - 9:
            raise _Malformed(f"the record at byte {pos} declares {length} bytes, {n - pos - 9} remain")
        yield pos, opcode, data[pos + 9:pos + 9 + length]
        pos += 9 + length


def _decompress(compression: str, data: memoryview, size: int) -> bytes:
    """Exactly ``size`` bytes of a chunk's records; raises ValueError naming what is wrong."""
    if size > MAX_CHUNK_BYTES:
        raise ValueError(f"it declares {size} uncompressed bytes (limit {MAX_CHUNK_BYTES >> 20} MiB)")
    try:
        if compression == "":
            out = bytes(data)
        elif compression == "zstd":
            with zstandard.ZstdDecompressor().stream_reader(io.BytesIO(data)) as reader:
                out = reader.read(size + 1)
        elif compression == "lz4":
            out = lz4.frame.LZ4FrameDecompressor().decompress(bytes(data), max_length=size + 1)
        else:
            raise ValueError(f"compression {compression!r} is not supported (expected zstd, lz4 or none)")
    except (zstandard.ZstdError, RuntimeError, MemoryError, OverflowError) as e:
        raise ValueError(f"{compression} data corrupt: {e}") from None
    if len(out) != size:
        raise ValueError(f"it holds {'more than' if len(out) > size else len(out)} of its declared {size} bytes")
    return out


class McapScan:
    """One front-to-back pass over an MCAP file: schemas and channels as they come, messages.

    ``messages()`` yields ``_Message`` records; damage is warned about through
    ``warn`` (chunk-level) and remembered in ``lost_bytes``, ``broken`` and
    ``last_time_ns`` for the caller's summary.
    """

    def __init__(self, path: str, warn: Callable, channels: dict, schemas: dict):
        self.path, self.warn = path, warn
        self.channels, self.schemas = channels, schemas
        self.lost_bytes, self.broken, self.footer = 0, None, False
        self.last_time_ns: int | None = None

    def _define(self, opcode: int, content: memoryview) -> None:
        f = _Fields(content)
        if opcode == _OP_SCHEMA:
            schema_id, name, encoding = f.int(2), f.string(), f.string()
            self.schemas[schema_id] = (name, encoding, bytes(f.take(f.int(4))))
        else:
            channel_id, schema_id, topic, encoding = f.int(2), f.int(2), f.string(), f.string()
            name, schema_encoding, data = self.schemas.get(schema_id, ("", "", b""))
            if encoding == "ros1" and name.count("/") == 1:   # ROS 1's pkg/Type, named as ROS 2's (and rosbags')
                name = name.replace("/", "/msg/")
            self.channels[channel_id] = _Channel(channel_id, name, topic, encoding, schema_id, schema_encoding, data)

    @staticmethod
    def _message(content: memoryview) -> _Message:
        f = _Fields(content)
        channel_id = f.int(2)
        f.int(4)
        log_time = f.int(8)
        f.int(8)
        return _Message(channel_id, log_time, f.rest())

    def _chunk(self, offset: int, content: memoryview) -> list[_Message]:
        f = _Fields(content)
        f.int(8), f.int(8)
        size, crc, compression = f.int(8), f.int(4), f.string()
        compressed = f.take(f.int(8))
        try:
            records = memoryview(_decompress(compression, compressed, size))
        except ValueError as e:
            self.warn("damaged chunk", "%s: chunk at byte %d damaged (%s): its messages skipped", self.path,
                      offset, e)
            return []
        messages, problem = [], None
        try:
            for _, opcode, inner in _records(records):
                if opcode == _OP_MESSAGE:
                    messages.append(self._message(inner))
                elif opcode in (_OP_SCHEMA, _OP_CHANNEL):
                    self._define(opcode, inner)
        except (_Malformed, UnicodeDecodeError) as e:
            problem = f"malformed record: {e}"
        if crc and zlib.crc32(records) != crc:
            self.warn("damaged chunk", "%s: chunk at byte %d damaged (CRC mismatch): its %d messages skipped",
                      self.path, offset, len(messages))
            return []
        if problem:
            self.warn("damaged chunk", "%s: chunk at byte %d damaged (%s): the %d messages before it are read",
                      self.path, offset, problem, len(messages))
        messages.sort(key=lambda m: m.log_time)
        return messages

    def messages(self) -> Iterator[_Message]:
        size = os.path.getsize(self.path)
        with open(self.path, "rb") as file:
            file.seek(len(MCAP_MAGIC))
            pos = len(MCAP_MAGIC)
            while True:
                header = file.read(9)
                if len(header) < 9:
                    self.broken = "no footer" if len(header) == 0 else f"a record header at byte {pos} is cut off"
                    break
                opcode, length = header[0], struct.unpack_from("<Q", header, 1)[0]
                if length > size - pos - 9:
                    self.broken = f"the record at byte {pos} declares {length} bytes, {size - pos - 9} remain"
                    break
                if opcode == _OP_FOOTER:
                    self.footer = True
                    break
                too_long = length > MAX_RECORD_BYTES
                if too_long and opcode in (_OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK):
                    self.warn("damaged record", "%s: record at byte %d declares %d bytes (limit %d): skipped",
                              self.path, pos, length, MAX_RECORD_BYTES)
                if too_long or opcode not in (_OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK):
                    file.seek(length, os.SEEK_CUR)
                    pos += 9 + length
                    continue
                content = memoryview(file.read(length))
                try:
                    if opcode == _OP_CHUNK:
                        batch = self._chunk(pos, content)
                    elif opcode == _OP_MESSAGE:
                        batch = [self._message(content)]
                    else:
                        self._define(opcode, content)
                        batch = []
                except (_Malformed, UnicodeDecodeError) as e:
                    self.warn("damaged record", "%s: record at byte %d damaged (%s): skipped", self.path, pos, e)
                    batch = []
                pos += 9 + length
                for message in batch:
                    self.last_time_ns = message.log_time
                    yield message
        if not self.footer:
            self.lost_bytes = size - pos
