"""The records of a ROS 1 bag file (format 2.0), read and rewritten, so
that the tests and the fuzzer (tests/fuzz) can damage a bag where a robot's
disk or network does: inside the data of a compressed chunk, before or
after the compression. Plain Python, no sfanav: the fuzzer imports it
before sfanav is instrumented.

A bag is ``#ROSBAG V2.0\\n`` and records; a record is a little-endian
uint32 header length, the header (fields: uint32 length, ``name=value``),
a uint32 data length and the data. A chunk (op 5) holds message and
connection records, compressed as its ``compression`` field says (``none``,
``bz2``, ``lz4``), ``size`` bytes once decompressed; the bag header (op 3)
gives the index's position (``index_pos``), each chunk info (op 6) its
chunk's (``chunk_pos``).
"""

from __future__ import annotations

import bz2
import struct
from dataclasses import dataclass

MAGIC = b"#ROSBAG V2.0\n"

BAG_HEADER, CHUNK, CHUNK_INFO = 3, 5, 6


@dataclass
class Record:
    """One record: where it starts, its header fields (name -> raw value)
    and where its data lies in the file."""

    start: int
    fields: dict[bytes, bytes]
    data_start: int
    data_end: int

    @property
    def op(self) -> int:
        """The record's op code; 0xff for a record without one (or with an empty one: a mutated bag)."""
        return (self.fields.get(b"op") or b"\xff")[0]


def records(data: bytes) -> list[Record]:
    """The records of a ROS 1 bag, up to the first that does not parse
    (a damaged or cut file yields the ones before the damage)."""
    out: list[Record] = []
    if not data.startswith(MAGIC):
        return out
    pos = len(MAGIC)
    while pos + 4 <= len(data):
        try:
            (hlen,) = struct.unpack_from("<I", data, pos)
            header = data[pos + 4 : pos + 4 + hlen]
            fields, q = {}, 0
            while q < len(header):
                (flen,) = struct.unpack_from("<I", header, q)
                name, _, value = header[q + 4 : q + 4 + flen].partition(b"=")
                fields[name] = value
                q += 4 + flen
            (dlen,) = struct.unpack_from("<I", data, pos + 4 + hlen)
        except struct.error:
            break
        start = pos + 8 + hlen
        if len(header) != hlen or start + dlen > len(data):
            break
        out.append(Record(pos, fields, start, start + dlen))
        pos = start + dlen
    return out


def _header_bytes(fields: dict[bytes, bytes]) -> bytes:
    parts = [name + b"=" + value for name, value in fields.items()]
    return b"".join(struct.pack("<I", len(p)) + p for p in parts)


def compress(raw: bytes, compression: str) -> bytes:
    """``raw`` as a chunk's data with ``compression`` (``none``, ``bz2``, ``lz4``: an LZ4 frame)."""
    if compression == "bz2":
        return bz2.compress(raw)
    if compression == "lz4":
        import lz4.frame

        return lz4.frame.compress(raw)
    return raw


def decompress(data: bytes, compression: str) -> bytes:
    if compression == "bz2":
        return bz2.decompress(data)
    if compression == "lz4":
        import lz4.frame

        return lz4.frame.decompress(data)
    return data


def chunks(data: bytes) -> list[Record]:
    """The chunk records of a bag."""
    return [r for r in records(data) if r.op == CHUNK]


def replace_chunk_data(data: bytes, chunk: Record, new: bytes, size: int | None = None) -> bytes:
    """The bag with ``chunk``'s data replaced by ``new`` (already
    compressed as the chunk says) and its ``size`` field set to ``size``
    (default: left as it is); the positions the bag header and the chunk
    infos give of what follows are moved by the change in length, so that
    the bag still opens and the reader meets the new data."""
    fields = dict(chunk.fields)
    if size is not None:
        fields[b"size"] = struct.pack("<I", size)
    header = _header_bytes(fields)
    record = struct.pack("<I", len(header)) + header + struct.pack("<I", len(new)) + new
    shift = chunk.start + len(record) - chunk.data_end
    out = bytearray(data[: chunk.start] + record + data[chunk.data_end :])
    # every position field after the chunk moves by ``shift``; the fields keep their sizes
    for r in records(bytes(out)):
        name = {BAG_HEADER: b"index_pos", CHUNK_INFO: b"chunk_pos"}.get(r.op)
        if name is None or len(r.fields.get(name, b"")) != 8:
            continue
        (old,) = struct.unpack("<Q", r.fields[name])
        if old > chunk.start:
            fields = dict(r.fields)
            fields[name] = struct.pack("<Q", old + shift)
            header = _header_bytes(fields)
            out[r.start + 4 : r.start + 4 + len(header)] = header  # same length: only a value changed
    return bytes(out)


def damage_chunk(data: bytes, chunk: Record, offsets: list[int], *, before_compression: bool) -> bytes:
    """The bag with the bytes at ``offsets`` (taken modulo the length)
    of ``chunk``'s data inverted: of the compressed data as stored (a
    damaged bz2 or lz4 stream), or of the decompressed records, compressed
    again (records that decompress but do not parse)."""
    compression = chunk.fields.get(b"compression", b"none").decode("latin-1")
    stored = data[chunk.data_start : chunk.data_end]
    target = bytearray(decompress(stored, compression) if before_compression else stored)
    if not target:
        return data
    for k in offsets:
        target[k % len(target)] ^= 0xFF
    if before_compression:
        return replace_chunk_data(data, chunk, compress(bytes(target), compression), len(target))
    return data[: chunk.data_start] + bytes(target) + data[chunk.data_end :]
