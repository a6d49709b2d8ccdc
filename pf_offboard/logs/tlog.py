"""MAVLink telemetry logs (``.tlog``), pymavlink's format, written and read.

Format (the one ``mavutil.mavlink_connection("x.tlog")``, ``mavlogdump.py`` and
MAVExplorer read): a sequence of records, each an 8-byte **big-endian unsigned microseconds
UNIX timestamp** followed by one raw MAVLink frame (v1 or v2, as sent on the wire). There is
no header and no direction field.

Direction convention: we log everything received *and* sent. A frame is ours ("out") when its
source component is one of ``own_component_ids`` — by default
``MAV_COMP_ID_ONBOARD_COMPUTER`` (191), the component id pf-offboard sends with — and, when
``own_system_id`` is given, its source system matches too. Everything else (the autopilot,
sysid 1 / compid 1 on PX4 and ArduPilot) is "in".

The reader is strict: a truncated record, a bad start-of-frame byte, a length mismatch or a
CRC failure raises :class:`LogError` naming the problem and the byte offset of the record.
A ``.tlog.gz`` is read transparently (offsets then count decompressed bytes).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, Literal

from pymavlink.dialects.v20 import ardupilotmega as mavlink_dialect

from pf_offboard.errors import InputError
from pf_offboard.logs._io import StreamWriter

#: MAV_COMP_ID_ONBOARD_COMPUTER: the component id pf-offboard's own frames carry.
OWN_COMPONENT_ID = 191

_STAMP = struct.Struct(">Q")
_MAGIC_V1 = 0xFE
_MAGIC_V2 = 0xFD
_HEADER_V1 = 6  # magic, len, seq, sysid, compid, msgid
_HEADER_V2 = 10  # magic, len, incompat, compat, seq, sysid, compid, msgid(3)
_CRC_LEN = 2
_SIGNATURE_LEN = 13
_IFLAG_SIGNED = 0x01
# Timestamps outside [1980, 2200) cannot come from a clock; they mean a damaged record.
_MIN_STAMP_US = 315_532_800 * 1_000_000
_MAX_STAMP_US = 7_258_118_400 * 1_000_000

Direction = Literal["in", "out"]
# A log read whole is at most this large (FlightLog bounds each file it writes to 2 GiB).
MAX_LOG_BYTES = 2 << 30


def check_log_file(p: Path) -> None:
    """A missing file, a FIFO, a device or one beyond the log size limit is refused (one
    :class:`InputError` naming the file) before a library (pymavlink, pyulog) opens it: it would
    block on a FIFO and read a huge file or a device on and on."""
    from pf_offboard.inputfile import check_bounded

    if not p.exists():
        raise InputError(str(p), "no such file")
    try:
        check_bounded(p, MAX_LOG_BYTES)
    except ValueError as exc:
        raise InputError(str(p), str(exc)) from None


class LogError(InputError):
    """A log file is corrupt, truncated or not in the expected format.

    ``field`` is ``"<path> @ byte <offset>"`` (or ``"<path> row <n>"`` for CSV logs).
    """


@dataclass(frozen=True)
class TlogEntry:
    """One record of a ``.tlog``: when it was logged, what, and which way it went."""

    time_unix_s: float  # UNIX time of logging, seconds (microsecond resolution)
    message: mavlink_dialect.MAVLink_message
    direction: Direction
    offset: int  # byte offset of the record (its timestamp) in the file
    frame: bytes  # the raw MAVLink frame as logged


class TlogWriter(StreamWriter):
    """Append MAVLink frames to a ``.tlog`` with their UNIX timestamps.

    Use as ``with TlogWriter.open(path) as w: w.write(frame_bytes, unix_time_s)``. The file
    is flushed on close; each record is written whole so a crash truncates at a record
    boundary in all but the last record.
    """

    def __init__(self, stream: BinaryIO) -> None:
        super().__init__(stream)
        self.records_written = 0

    @classmethod
    def open(cls, path: str | Path) -> TlogWriter:
        """Create (or truncate) ``path`` and return a writer that owns the file."""
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        return cls(p.open("wb"))

    def write(self, frame_bytes: bytes | bytearray, unix_time_s: float) -> None:
        """Log one raw MAVLink frame (as on the wire) at ``unix_time_s`` (seconds)."""
        if not frame_bytes or frame_bytes[0] not in (_MAGIC_V1, _MAGIC_V2):
            raise ValueError("frame_bytes: not a MAVLink frame (no 0xFE/0xFD start byte)")
        if not math.isfinite(unix_time_s) or unix_time_s < 0.0:
            raise ValueError(f"unix_time_s: must be finite and >= 0, got {unix_time_s!r}")
        self._stream.write(_STAMP.pack(int(round(unix_time_s * 1e6))) + bytes(frame_bytes))
        self.records_written += 1

    def write_message(self, message: mavlink_dialect.MAVLink_message, unix_time_s: float) -> None:
        """Log an already packed pymavlink message (its ``get_msgbuf()``)."""
        self.write(message.get_msgbuf(), unix_time_s)


def read_log_bytes(path: Path) -> bytes:
    """A log file's bytes; ``*.gz`` files are decompressed (offsets then count decompressed bytes)."""
    from pf_offboard.inputfile import gunzip_bounded, read_bounded

    name = str(path) if len(str(path)) <= 200 else str(path)[:100] + "..." + str(path)[-100:]
    try:
        data = read_bounded(path, MAX_LOG_BYTES)
        if path.name.endswith(".gz"):
            data = gunzip_bounded(data, MAX_LOG_BYTES)
    except ValueError as exc:
        raise LogError(name, str(exc)) from None
    return data


def _frame_length(data: bytes, start: int) -> int:
    """Total length of the MAVLink frame starting at ``data[start]`` (its first byte is valid)."""
    magic = data[start]
    payload_len = data[start + 1]
    if magic == _MAGIC_V1:
        return _HEADER_V1 + payload_len + _CRC_LEN
    incompat = data[start + 2]
    sig = _SIGNATURE_LEN if incompat & _IFLAG_SIGNED else 0
    return _HEADER_V2 + payload_len + _CRC_LEN + sig


def iter_tlog(
    path: str | Path,
    own_component_ids: tuple[int, ...] = (OWN_COMPONENT_ID,),
    own_system_id: int | None = None,
) -> Iterator[TlogEntry]:
    """Yield every record of a ``.tlog`` in file order.

    Raises :class:`LogError` (an :class:`InputError`) naming the problem and the byte
    offset on the first corrupt or truncated record; raises it too if the file is missing.
    """
    p = Path(path)
    data = read_log_bytes(p)
    if not data:
        raise LogError(str(p), "empty file, not a .tlog")
    mav = mavlink_dialect.MAVLink(None)
    offset = 0
    n = len(data)
    index = 0
    while offset < n:
        where = f"{p} @ byte {offset}"
        if n - offset < _STAMP.size + _HEADER_V1:
            raise LogError(where, f"truncated record {index}: {n - offset} trailing bytes, too short for a timestamp and frame header")
        (stamp_us,) = _STAMP.unpack_from(data, offset)
        if not _MIN_STAMP_US <= stamp_us < _MAX_STAMP_US:
            raise LogError(where, f"record {index}: timestamp {stamp_us} us is not a plausible UNIX time (corrupt record or not a .tlog)")
        start = offset + _STAMP.size
        magic = data[start]
        if magic not in (_MAGIC_V1, _MAGIC_V2):
            raise LogError(where, f"record {index}: bad MAVLink start byte 0x{magic:02X} at byte {start} (expected 0xFE or 0xFD)")
        if magic == _MAGIC_V2 and n - start < _HEADER_V2:
            raise LogError(where, f"truncated record {index}: MAVLink 2 header cut off at end of file")
        length = _frame_length(data, start)
        if n - start < length:
            raise LogError(where, f"truncated record {index}: frame needs {length} bytes, only {n - start} left in file")
        frame = data[start : start + length]
        try:
            message = mav.decode(bytearray(frame))
        except mavlink_dialect.MAVError as exc:
            raise LogError(where, f"record {index}: corrupt MAVLink frame: {exc}") from None
        src_sys = message.get_srcSystem()
        src_comp = message.get_srcComponent()
        ours = src_comp in own_component_ids and (own_system_id is None or src_sys == own_system_id)
        yield TlogEntry(
            time_unix_s=stamp_us * 1e-6,
            message=message,
            direction="out" if ours else "in",
            offset=offset,
            frame=frame,
        )
        offset = start + length
        index += 1


def read_tlog(
    path: str | Path,
    own_component_ids: tuple[int, ...] = (OWN_COMPONENT_ID,),
    own_system_id: int | None = None,
) -> list[TlogEntry]:
    """All records of a ``.tlog`` (see :func:`iter_tlog`); validates the whole file first."""
    return list(iter_tlog(path, own_component_ids, own_system_id))
