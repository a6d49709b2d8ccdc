"""Random thrown starts for a sweep, each drawn from its own seeded generator.

Flight ``i`` of a sweep with seed ``s`` draws everything from
``numpy.random.default_rng(SeedSequence(s, spawn_key=(i,)))``: the ``i``-th child of
``SeedSequence(s).spawn(n)``, whatever ``n``. So a flight's start depends only on ``(s, i)``: not on
how many flights the sweep has, the order they run in, or which process or machine runs them.

A start (world ENU, body FLU, metres, m/s, rad/s):

- position: a point drawn uniformly by arc length on the path, plus an offset of length uniform in
  ``[0, max_distance_m]`` in a uniformly random direction; redrawn while below ``min_height_m``;
- velocity: speed uniform in ``[0, max_speed_m_s]``, direction uniform on the sphere;
- attitude: yaw uniform, tilt (angle of the body z axis from the vertical) uniform in
  ``[0, max_tilt_deg]`` about a horizontal axis of uniform direction;
- body rates: magnitude uniform in ``[0, max_rate_rad_s]``, axis uniform on the sphere;
- wind: horizontal, speed uniform in ``[0, max_wind_m_s]``, direction uniform;
- the simulation's own seed (sensor noise, estimator error), drawn last.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from pf_offboard.errors import InputError
from pf_offboard.frames import quat_multiply

MAX_FLIGHTS = 1_000_000  # flight indices stay below the spawn key of the gain candidates
GAINS_SPAWN_KEY = 1 << 32  # SeedSequence(seed, spawn_key=(GAINS_SPAWN_KEY,)) draws random gains
MAX_DRAWS = 1000  # position redraws before giving up on min_height_m


@dataclass(frozen=True)
class StartRanges:
    """The box the starts are drawn from (see the module docstring)."""

    max_distance_m: float = 5.0
    max_speed_m_s: float = 4.0
    max_tilt_deg: float = 45.0
    max_rate_rad_s: float = 2.0
    max_wind_m_s: float = 3.0
    min_height_m: float = 2.0

    def validate(self) -> StartRanges:
        """Self, or an InputError naming the sweep flag that is out of range."""
        bounds = (
            ("--max-distance", self.max_distance_m, 50.0),
            ("--max-speed", self.max_speed_m_s, 30.0),
            ("--max-tilt", self.max_tilt_deg, 180.0),
            ("--max-rate", self.max_rate_rad_s, 35.0),
            ("--max-wind", self.max_wind_m_s, 20.0),
            ("--min-height", self.min_height_m, 100.0),
        )
        for flag, value, hi in bounds:
            if not (math.isfinite(value) and 0.0 <= value <= hi):
                raise InputError(flag, f"must be in [0, {hi:g}], got {value}")
        if self.min_height_m < 0.3:
            raise InputError("--min-height", f"must be >= 0.3 m (a start in the air), got {self.min_height_m}")
        return self


@dataclass(frozen=True)
class Start:
    """One drawn start: what :class:`pf_offboard.sim.SimSpec` needs for a thrown flight."""

    index: int
    position_enu_m: tuple[float, float, float]
    velocity_enu_m_s: tuple[float, float, float]
    q_enu_flu: tuple[float, float, float, float]  # body FLU -> world ENU, (w, x, y, z)
    body_rates_flu_rad_s: tuple[float, float, float]
    wind_enu_m_s: tuple[float, float, float]
    sim_seed: int
    distance_m: float  # from the path at the start

    @property
    def speed_m_s(self) -> float:
        return math.hypot(*self.velocity_enu_m_s)

    @property
    def tilt_deg(self) -> float:
        """Angle between the body z axis and the vertical."""
        w, x, y, _ = self.q_enu_flu
        return math.degrees(math.acos(max(-1.0, min(1.0, 1.0 - 2.0 * (x * x + y * y)))))

    def columns(self) -> dict[str, Any]:
        """The start as flat table columns (units in the names)."""
        out: dict[str, Any] = {"flight": self.index, "sim_seed": self.sim_seed}
        for name, values, axes in (
            ("pos_enu_{}_m", self.position_enu_m, "xyz"),
            ("vel_enu_{}_m_s", self.velocity_enu_m_s, "xyz"),
            ("q_enu_flu_{}", self.q_enu_flu, "wxyz"),
            ("rate_flu_{}_rad_s", self.body_rates_flu_rad_s, "xyz"),
            ("wind_enu_{}_m_s", self.wind_enu_m_s, "xyz"),
        ):
            out.update({name.format(a): float(v) for a, v in zip(axes, values)})
        out.update({
            "distance_m": self.distance_m,
            "speed_m_s": self.speed_m_s,
            "tilt_deg": self.tilt_deg,
            "rate_rad_s": math.hypot(*self.body_rates_flu_rad_s),
            "wind_m_s": math.hypot(*self.wind_enu_m_s),
        })  # fmt: skip
        return out


def flight_rng(seed: int, index: int) -> np.random.Generator:
    """The generator of flight ``index``: child ``index`` of ``SeedSequence(seed)``."""
    if not 0 <= index < MAX_FLIGHTS:
        raise InputError("--flights", f"flight index must be in [0, {MAX_FLIGHTS}), got {index}")
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(index,)))


def _unit(rng: np.random.Generator) -> np.ndarray:
    """A direction uniform on the unit sphere."""
    z = rng.uniform(-1.0, 1.0)
    a = rng.uniform(0.0, 2.0 * math.pi)
    r = math.sqrt(max(0.0, 1.0 - z * z))
    return np.array([r * math.cos(a), r * math.sin(a), z])


def sample_start(path: Any, ranges: StartRanges, seed: int, index: int) -> Start:
    """Draw flight ``index``'s start around ``path`` (a :class:`pf_offboard.path.Path`)."""
    from pf_offboard.path.projection import Projector

    rng = flight_rng(seed, index)
    for _ in range(MAX_DRAWS):
        s_m = rng.uniform(0.0, path.length_m)
        on_path = np.asarray(path.eval(path.lam_at_arclength(s_m)).sigma, dtype=float)
        position = on_path + rng.uniform(0.0, ranges.max_distance_m) * _unit(rng)
        if position[2] >= ranges.min_height_m:
            break
    else:
        raise InputError("--min-height", f"no start within {ranges.max_distance_m:g} m of the path is above "
                         f"{ranges.min_height_m:g} m (after {MAX_DRAWS} draws)")  # fmt: skip
    velocity = rng.uniform(0.0, ranges.max_speed_m_s) * _unit(rng)
    yaw = rng.uniform(-math.pi, math.pi)
    tilt = math.radians(rng.uniform(0.0, ranges.max_tilt_deg))
    axis_rad = rng.uniform(0.0, 2.0 * math.pi)
    q_yaw = (math.cos(0.5 * yaw), 0.0, 0.0, math.sin(0.5 * yaw))
    h = math.sin(0.5 * tilt)
    q_tilt = (math.cos(0.5 * tilt), h * math.cos(axis_rad), h * math.sin(axis_rad), 0.0)  # about a world-horizontal axis
    q = quat_multiply(q_tilt, q_yaw)
    rates = rng.uniform(0.0, ranges.max_rate_rad_s) * _unit(rng)
    wind_speed = rng.uniform(0.0, ranges.max_wind_m_s)
    wind_dir = rng.uniform(0.0, 2.0 * math.pi)
    sim_seed = int(rng.integers(0, 2**63 - 1))
    projector = Projector(path)
    projector.update(position)
    return Start(
        index=index,
        position_enu_m=tuple(float(v) for v in position),  # type: ignore[arg-type]
        velocity_enu_m_s=tuple(float(v) for v in velocity),  # type: ignore[arg-type]
        q_enu_flu=tuple(float(v) for v in q),  # type: ignore[arg-type]
        body_rates_flu_rad_s=tuple(float(v) for v in rates),  # type: ignore[arg-type]
        wind_enu_m_s=(wind_speed * math.cos(wind_dir), wind_speed * math.sin(wind_dir), 0.0),
        sim_seed=sim_seed,
        distance_m=float(projector.distance_m),
    )
