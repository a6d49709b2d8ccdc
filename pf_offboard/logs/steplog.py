"""Per-step controller log: one :class:`StepRecord` per controller step, as CSV.

Frames and units are in the names: world ENU (z up), body FLU, metres, seconds, radians,
mass-normalised thrust in m/s^2. Vector fields become one column per component
(``position_enu_m_x``, ``q_cmd_enu_flu_w`` ...); booleans are written ``0``/``1``; floats
with ``repr`` (shortest round-trip form), so reading a log back gives bit-identical values.
"""

from __future__ import annotations

import csv
import dataclasses
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pf_offboard.logs._io import StreamWriter
from pf_offboard.logs.tlog import LogError, read_log_bytes

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]


@dataclass(frozen=True)
class StepRecord:
    """What the controller saw and commanded at one step (ENU / FLU, SI units).

    Vector fields accept any 3- (or 4-) sequence or array and are stored as tuples of float.
    Commands are NaN when the controller produced none (e.g. before activation).
    """

    time_s: float  # vehicle time (autopilot clock), s
    mode: str  # pipeline / bridge mode, e.g. "waiting", "following", "handed_back"
    active: bool  # the path-following setpoint was streamed this step
    position_enu_m: Vec3
    velocity_enu_m_s: Vec3
    lam: float  # path parameter of the closest point
    eta1_m: float  # arclength along the path
    eta2_m_s: float  # speed along the path
    xi1_m: float  # transversal position, along e2
    xi2_m_s: float
    phi1_m: float  # transversal position, along e3
    phi2_m_s: float
    cross_track_m: float
    speed_ref_m_s: float  # eta2 reference
    accel_cmd_enu_m_s2: Vec3  # gravity excluded
    thrust_cmd_m_s2: float  # mass-normalised collective thrust
    q_cmd_enu_flu: Quat  # (w, x, y, z), body FLU -> world ENU
    rates_cmd_flu_rad_s: Vec3
    yaw_cmd_rad: float  # ENU yaw
    yaw_rate_cmd_rad_s: float
    sat_tangential: bool
    sat_transversal: bool
    sat_tilt: bool
    sat_thrust: bool
    sat_approach_speed: bool
    event: str = ""  # "", "activated", "takeover", ...

    def __post_init__(self) -> None:
        # written into the instance's __dict__ (what object.__setattr__ does for a frozen dataclass
        # without slots), field by field in order: this runs once per controller step
        d = self.__dict__
        for name, kind, size in _KINDS:
            if kind == "float":
                d[name] = float(d[name])
            elif kind == "vec":
                vec = tuple(map(float, d[name]))
                if len(vec) != size:
                    raise ValueError(f"StepRecord.{name}: expected {size} components, got {len(vec)}")
                d[name] = vec
            elif kind == "bool":
                d[name] = bool(d[name])
            else:
                d[name] = str(d[name])


_VECTOR_SIZES: dict[str, int] = {
    "position_enu_m": 3,
    "velocity_enu_m_s": 3,
    "accel_cmd_enu_m_s2": 3,
    "q_cmd_enu_flu": 4,
    "rates_cmd_flu_rad_s": 3,
}
_BOOL_FIELDS = frozenset({"active", "sat_tangential", "sat_transversal", "sat_tilt", "sat_thrust", "sat_approach_speed"})
_STR_FIELDS = frozenset({"mode", "event"})
_FIELDS = dataclasses.fields(StepRecord)
# (name, kind, size) per field, in order: what __post_init__ normalises (computed once).
_KINDS: tuple[tuple[str, str, int], ...] = tuple(
    (f.name, "vec", _VECTOR_SIZES[f.name]) if f.name in _VECTOR_SIZES
    else (f.name, "bool", 1) if f.name in _BOOL_FIELDS
    else (f.name, "str", 1) if f.name in _STR_FIELDS
    else (f.name, "float", 1)
    for f in _FIELDS
)  # fmt: skip
_SUFFIX = {3: ("x", "y", "z"), 4: ("w", "x", "y", "z")}


def _columns() -> tuple[str, ...]:
    cols: list[str] = []
    for f in _FIELDS:
        if f.name in _VECTOR_SIZES:
            cols.extend(f"{f.name}_{s}" for s in _SUFFIX[_VECTOR_SIZES[f.name]])
        else:
            cols.append(f.name)
    return tuple(cols)


#: The CSV header, in order.
COLUMNS: tuple[str, ...] = _columns()


def record_to_row(record: StepRecord) -> list[str]:
    """Flat CSV cells of one record (floats as ``repr``, bools as 0/1)."""
    row: list[str] = []
    d = record.__dict__
    for name, kind, _ in _KINDS:
        value = d[name]
        if kind == "float":
            row.append(repr(float(value)))
        elif kind == "vec":
            row += [repr(float(x)) for x in value]
        elif kind == "bool":
            row.append("1" if value else "0")
        else:
            row.append(value)
    return row


class StepLogWriter(StreamWriter):
    """Write :class:`StepRecord` rows to a CSV file with the :data:`COLUMNS` header.

    ``with StepLogWriter.open(path) as w: w.write(record)``.
    """

    _FLUSH_EVERY = 250  # rows; a crash loses at most about a second of a 250 Hz log

    def __init__(self, stream: TextIO) -> None:
        super().__init__(stream)
        self._csv = csv.writer(stream, lineterminator="\n")
        self._csv.writerow(COLUMNS)
        self.rows_written = 0

    @classmethod
    def open(cls, path: str | Path) -> StepLogWriter:
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        return cls(p.open("w", newline="", encoding="utf-8"))

    def write(self, record: StepRecord) -> None:
        self._csv.writerow(record_to_row(record))
        self.rows_written += 1
        if self.rows_written % self._FLUSH_EVERY == 0:
            self._stream.flush()

    def write_all(self, records: Iterable[StepRecord]) -> None:
        for r in records:
            self.write(r)


def _parse_float(text: str, where: str, column: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise LogError(where, f"column {column!r}: not a number: {text!r}") from None


def _parse_bool(text: str, where: str, column: str) -> bool:
    if text in ("1", "True", "true"):
        return True
    if text in ("0", "False", "false"):
        return False
    raise LogError(where, f"column {column!r}: expected 0 or 1, got {text!r}")


def row_to_record(row: Sequence[str], where: str) -> StepRecord:
    """Parse one CSV row (already checked to have ``len(COLUMNS)`` cells)."""
    values: dict[str, object] = {}
    i = 0
    for name, kind, size in _KINDS:
        if kind == "float":
            values[name] = _parse_float(row[i], where, COLUMNS[i])
        elif kind == "vec":
            values[name] = tuple([_parse_float(row[i + k], where, COLUMNS[i + k]) for k in range(size)])
        elif kind == "bool":
            values[name] = _parse_bool(row[i], where, COLUMNS[i])
        else:
            values[name] = row[i]
        i += size
    return StepRecord(**values)  # type: ignore[arg-type]


def read_steplog(path: str | Path) -> list[StepRecord]:
    """Read a step-log CSV written by :class:`StepLogWriter`.

    Raises :class:`LogError` naming the file, row (1-based, header is row 1) and column
    on a missing/unknown header, a short or long row, or an unparsable cell. ``*.csv.gz`` is
    read transparently.
    """
    p = Path(path)
    try:
        text = read_log_bytes(p).decode("utf-8")
    except UnicodeDecodeError as exc:
        raise LogError(f"{p} @ byte {exc.start}", "not UTF-8 text, not a step-log CSV") from None
    reader = csv.reader(text.splitlines())
    try:
        header = next(reader)
    except StopIteration:
        raise LogError(str(p), "empty file, no CSV header") from None
    if tuple(header) != COLUMNS:
        missing = [c for c in COLUMNS if c not in header]
        extra = [c for c in header if c not in COLUMNS]
        detail = f"missing {missing[:3]}" if missing else f"unexpected {extra[:3]}" if extra else "columns out of order"
        raise LogError(f"{p} row 1", f"not a pf-offboard step-log header ({detail})")
    records: list[StepRecord] = []
    name = str(p)
    for row_no, row in enumerate(reader, start=2):
        where = f"{name} row {row_no}"
        if len(row) != len(COLUMNS):
            raise LogError(where, f"expected {len(COLUMNS)} cells, got {len(row)} (truncated or corrupt row)")
        records.append(row_to_record(row, where))
    return records


def column(records: Sequence[StepRecord], name: str) -> NDArray[np.float64]:
    """One field of all records as an array: shape (N,) for scalars, (N, k) for vectors."""
    if name not in {f.name for f in _FIELDS}:
        raise KeyError(name)
    values: list[ArrayLike] = [getattr(r, name) for r in records]
    if name in _STR_FIELDS:
        raise TypeError(f"{name} is a text field")
    if not values:
        size = _VECTOR_SIZES.get(name)
        return np.zeros((0, size) if size else (0,))
    return np.asarray(values, dtype=float)


def is_finite_command(record: StepRecord) -> bool:
    """True when the record carries a real command (not the NaN placeholders)."""
    return all(math.isfinite(x) for x in record.accel_cmd_enu_m_s2) and math.isfinite(record.thrust_cmd_m_s2)
