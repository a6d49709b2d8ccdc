"""The files one flight leaves behind, written the same way by ``fly`` and ``sim``.

``DIR/<name>.tlog`` — every MAVLink frame received and sent (see :mod:`.tlog`);
``DIR/<name>.csv`` — one :class:`~pf_offboard.logs.steplog.StepRecord` per controller step;
``DIR/<name>.yaml`` — a copy of the config flown (so ``replay`` / ``plot`` can find it).
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

from pf_offboard.logs._io import Closing
from pf_offboard.logs.steplog import StepLogWriter, StepRecord
from pf_offboard.logs.tlog import TlogWriter


@dataclass(frozen=True)
class FlightLogPaths:
    """Where one flight's logs live: ``<dir>/<name>.tlog|.csv|.yaml``."""

    tlog: Path
    steps_csv: Path
    config_yaml: Path

    @classmethod
    def in_dir(cls, out_dir: str | Path, name: str = "flight") -> FlightLogPaths:
        d = Path(out_dir)
        return cls(d / f"{name}.tlog", d / f"{name}.csv", d / f"{name}.yaml")

    @classmethod
    def beside(cls, log_path: str | Path) -> FlightLogPaths:
        """The sibling files of a ``.tlog`` or ``.csv`` (same directory and stem); a gzipped
        log (``x.tlog.gz``) has gzipped siblings (``x.csv.gz``) and a plain ``x.yaml``."""
        p = Path(log_path)
        ext = ".gz" if p.name.endswith(".gz") else ""
        stem = log_stem(p)
        return cls(p.with_name(f"{stem}.tlog{ext}"), p.with_name(f"{stem}.csv{ext}"), p.with_name(f"{stem}.yaml"))


def log_stem(path: str | Path) -> str:
    """``flight`` for ``flight.tlog``, ``flight.csv``, ``flight.tlog.gz`` ..."""
    name = Path(path).name
    if name.endswith(".gz"):
        name = name[:-3]
    return name.rsplit(".", 1)[0] if "." in name else name


class FlightLog(Closing):
    """Writers for one flight: ``with FlightLog.open(out_dir) as log: log.frame(...)``.

    ``frame(bytes, unix_time_s)`` logs MAVLink traffic in either direction (the direction is
    recovered from the source component, see :mod:`.tlog`); ``step(record)`` logs a
    controller step.
    """

    def __init__(self, paths: FlightLogPaths, tlog: TlogWriter, steps: StepLogWriter) -> None:
        self.paths = paths
        self._tlog = tlog
        self._steps = steps

    @classmethod
    def open(cls, out_dir: str | Path, name: str = "flight", config_path: str | Path | None = None) -> FlightLog:
        """Create the directory and files (overwriting a previous flight of the same name)."""
        paths = FlightLogPaths.in_dir(out_dir, name)
        paths.tlog.parent.mkdir(parents=True, exist_ok=True)
        if config_path is not None and Path(config_path).resolve() != paths.config_yaml.resolve():
            shutil.copyfile(config_path, paths.config_yaml)
        return cls(paths, TlogWriter.open(paths.tlog), StepLogWriter.open(paths.steps_csv))

    def frame(self, frame_bytes: bytes | bytearray, unix_time_s: float) -> None:
        self._tlog.write(frame_bytes, unix_time_s)

    def step(self, record: StepRecord) -> None:
        self._steps.write(record)

    def flush(self) -> None:
        self._tlog.flush()

    def close(self) -> None:
        self._tlog.close()
        self._steps.close()
