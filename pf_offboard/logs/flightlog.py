"""The files one flight leaves behind, written the same way by ``fly`` and ``sim``.

``DIR/<name>.tlog`` — every MAVLink frame received and sent (see :mod:`.tlog`);
``DIR/<name>.csv`` — one :class:`~pf_offboard.logs.steplog.StepRecord` per controller step;
``DIR/<name>.yaml`` — a copy of the config flown (so ``replay`` / ``plot`` can find it).
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

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
    def open(cls, out_dir: str | Path, name: str = "flight", config_path: str | Path | None = None, config: Any = None) -> FlightLog:
        """Create the directory and files (overwriting a previous flight of the same name).

        ``config``: the loaded config; when its path came from a planning tool's file and was
        converted to local way-points, the copy holds those (see :meth:`write_config`)."""
        paths = FlightLogPaths.in_dir(out_dir, name)
        paths.tlog.parent.mkdir(parents=True, exist_ok=True)
        log = cls(paths, TlogWriter.open(paths.tlog), StepLogWriter.open(paths.steps_csv))
        if config_path is not None:
            log.write_config(config_path, config)
        return log

    def write_config(self, config_path: str | Path, config: Any = None) -> None:
        """Copy the config flown beside the logs. A geodetic path (``path.file``) already converted
        to the local frame is written as its local ENU way-points, with the file, origin and
        altitude reference in a comment: replay and plot then rebuild exactly the path flown."""
        target = self.paths.config_yaml
        geodetic = getattr(getattr(config, "path", None), "geodetic", None)
        if geodetic is None or not config.path.waypoints_enu_m:
            if Path(config_path).resolve() != target.resolve():
                shutil.copyfile(config_path, target)
            return
        import yaml

        from pf_offboard.config import local_config_data

        data = yaml.safe_load(Path(config_path).read_text(encoding="utf-8"))
        o = geodetic.origin
        header = (
            f"# Flown from {config_path}: path.file {geodetic.file} ({geodetic.file_format}, altitudes {geodetic.altitude_reference}),\n"
            f"# converted to local ENU metres at the origin lat {o.lat_deg!r} deg, lon {o.lon_deg!r} deg, alt {o.alt_amsl_m!r} m AMSL"
            + (f" (home at {geodetic.home_alt_amsl_m!r} m AMSL)" if geodetic.home_alt_amsl_m is not None else "")
            + ".\n"
        )
        target.write_text(header + yaml.safe_dump(local_config_data(config, data), sort_keys=False), encoding="utf-8")

    def frame(self, frame_bytes: bytes | bytearray, unix_time_s: float) -> None:
        self._tlog.write(frame_bytes, unix_time_s)

    def step(self, record: StepRecord) -> None:
        self._steps.write(record)

    def flush(self) -> None:
        self._tlog.flush()

    def close(self) -> None:
        self._tlog.close()
        self._steps.close()
