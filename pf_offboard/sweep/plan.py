"""A whole sweep: draw the starts, build the tasks, run them, write the outputs."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from pf_offboard.errors import InputError
from pf_offboard.sweep.gains import GainCandidate
from pf_offboard.sweep.runner import FlightSettings, FlightTask, execute
from pf_offboard.sweep.starts import MAX_FLIGHTS, StartRanges, sample_start


@dataclass(frozen=True)
class SweepSpec:
    """What to sweep: ``flights`` starts from ``seed`` (each candidate of ``gains`` flies all)."""

    flights: int = 100
    seed: int = 0
    ranges: StartRanges = field(default_factory=StartRanges)
    settings: FlightSettings = field(default_factory=FlightSettings)
    gains: tuple[GainCandidate, ...] = ()
    # several vehicle presets: every candidate flies every start on each (settings.vehicle unused)
    vehicles: tuple[str, ...] = ()

    @property
    def flight_settings(self) -> tuple[FlightSettings, ...]:
        """One FlightSettings per vehicle flown."""
        from dataclasses import replace

        return tuple(replace(self.settings, vehicle=v) for v in self.vehicles) if self.vehicles else (self.settings,)

    @property
    def total_flights(self) -> int:
        return self.flights * max(1, len(self.gains)) * max(1, len(self.vehicles))

    def validate(self) -> SweepSpec:
        if not 1 <= self.flights <= MAX_FLIGHTS:
            raise InputError("--flights", f"must be in [1, {MAX_FLIGHTS}], got {self.flights}")
        if not 0 <= self.seed < 2**63:
            raise InputError("--seed", f"must be an integer in [0, 2^63), got {self.seed}")
        self.ranges.validate()
        self.settings.validate()
        return self


@dataclass
class SweepResult:
    rows: list[dict[str, Any]]
    wall_s: float
    executor: str


def config_yaml(config_path: str | Path, gains: GainCandidate | None = None) -> str:
    """The config as self-contained YAML text (a geodetic path as its local way-points), flying
    ``gains`` when given; validated, so a worker never meets a bad config."""
    import yaml

    from pf_offboard.config import load_config, local_config_data, parse_config

    config = load_config(config_path).require_local("a sweep flies in the local frame")
    data = yaml.safe_load(Path(config_path).read_text(encoding="utf-8"))
    if config.path.geodetic is not None:
        data = local_config_data(config, data)
    if gains is not None:
        from pf_offboard.sweep.gains import with_gains

        data = with_gains(data, gains)
        parse_config(data, source=f"{config_path} with gains {gains.bandwidth_hz:.3g} Hz / {gains.damping:.3g}")
    return yaml.safe_dump(data, sort_keys=False)


def tasks(config_path: str | Path, spec: SweepSpec, logs_dir: str | Path | None = None) -> list[FlightTask]:
    """Every flight of the sweep (each candidate × each start), in (candidate, flight) order."""
    from pf_offboard.control import PathFollower
    from pf_offboard.sim.flight import _check as check_sim
    from pf_offboard.sim.flight import SimSpec

    spec.validate()
    s = spec.settings
    # the flags a SimSpec checks (vehicle, autopilot, rate), named as the sim names them
    for fs in spec.flight_settings:
        check_sim(SimSpec(throw_enu=(0.0, 0.0, 10.0, 0.0, 0.0, 0.0), autopilot=fs.autopilot, vehicle=fs.vehicle,
                          rate_hz=fs.rate_hz, duration_s=fs.duration_s))  # fmt: skip
    base = config_yaml(config_path)
    from pf_offboard.config import load_config

    path = PathFollower.from_config(load_config(config_path).require_local()).path
    starts = [sample_start(path, spec.ranges, spec.seed, i) for i in range(spec.flights)]
    logs = str(logs_dir) if logs_dir is not None else None
    texts = [(None, base)] if not spec.gains else [(cand, config_yaml(config_path, cand)) for cand in spec.gains]
    out = []
    several = len(spec.vehicles) > 1
    for k, fs in enumerate(spec.flight_settings):
        for cand, text in texts:
            out.extend(FlightTask(st, text, fs, cand, logs, k if several else None) for st in starts)
    return out


def run(config_path: str | Path, spec: SweepSpec, workers: int = 1, cluster: str | None = None,
        on_row: Callable[[dict[str, Any]], None] | None = None, logs_dir: str | Path | None = None,
        client: Any = None, engine: str = "batch") -> SweepResult:  # fmt: skip
    """Run every flight (see :func:`pf_offboard.sweep.runner.execute`) and time it."""
    todo = tasks(config_path, spec, logs_dir)
    t0 = time.perf_counter()
    rows = execute(todo, workers, cluster, on_row, client=client, engine=engine)
    wall = time.perf_counter() - t0
    executor = (f"dask {cluster}" if cluster else "dask client") if (cluster or client is not None) else (
        "serial" if workers == 1 else f"process pool ({workers} workers)")  # fmt: skip
    return SweepResult(rows, wall, executor)


def settings_dict(spec: SweepSpec) -> dict[str, Any]:
    out = {"flights": spec.flights, "seed": spec.seed, "ranges": asdict(spec.ranges), "flight": asdict(spec.settings),
           "gain_candidates": len(spec.gains)}  # fmt: skip
    if spec.vehicles:
        out["vehicles"] = list(spec.vehicles)
    return out
