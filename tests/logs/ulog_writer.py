"""A minimal ULog writer for tests: one topic of float fields after a uint64 timestamp, in the
file format PX4's logger writes (header, format, add-logged, data messages) and pyulog reads."""

from __future__ import annotations

import struct
from collections.abc import Sequence
from pathlib import Path

MAGIC = b"ULog\x01\x12\x35"


def _msg(kind: bytes, payload: bytes) -> bytes:
    return struct.pack("<HB", len(payload), kind[0]) + payload


def write_ulog(path: Path, topic: str, fields: Sequence[str], time_us: Sequence[int], rows: Sequence[Sequence[float]]) -> Path:
    """``topic`` with ``uint64_t timestamp`` and float ``fields``, one data message per row."""
    out = bytearray(MAGIC + b"\x01" + struct.pack("<Q", int(time_us[0]) if len(time_us) else 0))
    out += _msg(b"B", bytes(8) + bytes(8) + bytes(24))  # flag bits: no compat/incompat flags, no appended data
    fmt = f"{topic}:uint64_t timestamp;" + "".join(f"float {f};" for f in fields)
    out += _msg(b"F", fmt.encode())
    out += _msg(b"A", struct.pack("<BH", 0, 0) + topic.encode())
    for t, row in zip(time_us, rows):
        out += _msg(b"D", struct.pack("<HQ", 0, int(t)) + struct.pack(f"<{len(fields)}f", *row))
    path.write_bytes(bytes(out))
    return path
