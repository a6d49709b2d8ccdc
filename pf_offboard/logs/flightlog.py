"""The files one flight leaves behind, written the same way by ``fly`` and ``sim``.

``DIR/<name>.tlog`` — every MAVLink frame received and sent (see :mod:`.tlog`);
``DIR/<name>.csv`` — one :class:`~pf_offboard.logs.steplog.StepRecord` per controller step;
``DIR/<name>.yaml`` — a copy of the config flown (so ``replay`` / ``plot`` can find it).
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
import sys
from collections.abc import Callable
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


# Each log file stops growing at this size by default (a warning says so): 250 Hz of telemetry and
# setpoints is ~320 MB of tlog an hour; 2 GiB is over six hours of flight.
DEFAULT_MAX_FILE_BYTES = 2 << 30


def _stderr_warning(text: str) -> None:
    print(f"warning: {text}", file=sys.stderr)


class FlightLog(Closing):
    """Writers for one flight: ``with FlightLog.open(out_dir) as log: log.frame(...)``.

    ``frame(bytes, unix_time_s)`` logs MAVLink traffic in either direction (the direction is
    recovered from the source component, see :mod:`.tlog`); ``step(record)`` logs a
    controller step.

    Flight control never depends on logging: an I/O error while writing (a full disk: ENOSPC, a
    removed USB stick: EIO) stops that file, with one ``warn`` line naming it, and is never raised
    to the caller (the receive callback, the keep-alive, the controller step); neither is one from
    ``flush`` or ``close``. Each file also stops at ``max_file_bytes`` (one warning). ``errors``
    lists what stopped a file.
    """

    def __init__(
        self, paths: FlightLogPaths, tlog: TlogWriter, steps: StepLogWriter,
        warn: Callable[[str], None] | None = None, max_file_bytes: int = DEFAULT_MAX_FILE_BYTES,
    ) -> None:  # fmt: skip
        self.paths = paths
        self._tlog: TlogWriter | None = tlog
        self._steps: StepLogWriter | None = steps
        self.warn = warn if warn is not None else _stderr_warning
        self.max_file_bytes = max_file_bytes
        self._tlog_bytes = 0
        self._steps_rows = 0
        self.errors: list[str] = []

    def _stop(self, which: str, why: str) -> None:
        """Stop writing one file (closing it quietly) and warn once."""
        writer = self._tlog if which == "tlog" else self._steps
        if which == "tlog":
            self._tlog = None
        else:
            self._steps = None
        path = self.paths.tlog if which == "tlog" else self.paths.steps_csv
        if writer is not None:
            try:
                writer.close()
            except OSError:
                pass
        text = f"log {path} stopped: {why}; the flight goes on without it"
        self.errors.append(text)
        try:
            self.warn(text)
        except Exception:  # noqa: BLE001  (a broken status stream must not end the flight either)
            pass

    @classmethod
    def open(
        cls, out_dir: str | Path, name: str = "flight", config_path: str | Path | None = None, config: Any = None,
        warn: Callable[[str], None] | None = None, max_file_bytes: int = DEFAULT_MAX_FILE_BYTES,
    ) -> FlightLog:  # fmt: skip
        """Create the directory and files (overwriting a previous flight of the same name).

        ``config``: the loaded config; when its path came from a planning tool's file and was
        converted to local way-points, the copy holds those (see :meth:`write_config`)."""
        paths = FlightLogPaths.in_dir(out_dir, name)
        paths.tlog.parent.mkdir(parents=True, exist_ok=True)
        log = cls(paths, TlogWriter.open(paths.tlog), StepLogWriter.open(paths.steps_csv), warn=warn, max_file_bytes=max_file_bytes)
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
        tlog = self._tlog
        if tlog is None:
            return
        self._tlog_bytes += 8 + len(frame_bytes)
        if self._tlog_bytes > self.max_file_bytes:
            self._stop("tlog", f"reached its size limit ({self.max_file_bytes / 2**20:.0f} MiB)")
            return
        try:
            tlog.write(frame_bytes, unix_time_s)
        except OSError as exc:
            self._stop("tlog", f"write failed: {exc.strerror or exc}")

    def step(self, record: StepRecord) -> None:
        steps = self._steps
        if steps is None:
            return
        self._steps_rows += 1
        # a row is ~400 bytes: checked by count, not by formatting the row twice
        if self._steps_rows * 400 > self.max_file_bytes:
            self._stop("steps", f"reached its size limit ({self.max_file_bytes / 2**20:.0f} MiB)")
            return
        try:
            steps.write(record)
        except OSError as exc:
            self._stop("steps", f"write failed: {exc.strerror or exc}")

    def flush(self) -> None:
        if self._tlog is not None:
            try:
                self._tlog.flush()
            except OSError as exc:
                self._stop("tlog", f"write failed: {exc.strerror or exc}")

    def close(self) -> None:
        for which, writer in (("tlog", self._tlog), ("steps", self._steps)):
            if writer is None:
                continue
            try:
                writer.close()
            except OSError as exc:
                self._stop(which, f"write failed at close: {exc.strerror or exc}")
        self._tlog = self._steps = None
