"""Held-out paths nobody tuned on (the regression set's): way-points and minimal configs."""

from __future__ import annotations

import math
from pathlib import Path as FsPath
from typing import Any

import numpy as np
import yaml


def tilted_figure_eight() -> list[list[float]]:
    """A lemniscate 5 x 2.6 m crossing itself at the centre, tilted 20 deg about x and 10 about y."""
    pts = []
    n = 14
    ax, ay = math.radians(20.0), math.radians(10.0)
    for i in range(n):
        u = 2.0 * math.pi * i / n
        s = math.sin(u)
        x, y, z = 2.5 * math.cos(u) / (1 + s * s), 2.5 * math.sin(u) * math.cos(u) / (1 + s * s) * 1.0, 0.0
        y, z = y * math.cos(ax) - z * math.sin(ax), y * math.sin(ax) + z * math.cos(ax)
        x, z = x * math.cos(ay) + z * math.sin(ay), -x * math.sin(ay) + z * math.cos(ay)
        pts.append([round(x, 4), round(y, 4), round(z + 2.5, 4)])
    return pts


def helix() -> list[list[float]]:
    """Open helix, radius 1.3 m, 3 turns climbing 1.8 m (a path with torsion, 25 m long)."""
    n, turns = 25, 3.0
    return [[round(1.3 * math.cos(turns * 2 * math.pi * i / (n - 1)), 4), round(1.3 * math.sin(turns * 2 * math.pi * i / (n - 1)), 4),
             round(1.6 + 1.8 * i / (n - 1), 4)] for i in range(n)]  # fmt: skip


def racetrack() -> list[list[float]]:
    """A 6 m x 2.4 m stadium at 2.2 m: 3 m straights, half-turns of radius 1.2 m."""
    r, h = 1.2, 1.5
    pts = [[-h, -r], [0.0, -r], [h, -r]]
    pts += [[h + r * math.sin(a), -r * math.cos(a)] for a in (math.pi / 4, math.pi / 2, 3 * math.pi / 4)]
    pts += [[h, r], [0.0, r], [-h, r]]
    pts += [[-h - r * math.sin(a), r * math.cos(a)] for a in (math.pi / 4, math.pi / 2, 3 * math.pi / 4)]
    return [[round(x, 4), round(y, 4), 2.2] for x, y in pts]


def random_closed(seed: int = 7) -> list[list[float]]:
    """A random smooth closed curve: a radius and height perturbed by low harmonics (seeded)."""
    rng = np.random.default_rng(seed)
    a, b = rng.normal(0.0, 0.25, 3), rng.uniform(0, 2 * math.pi, 3)
    c = rng.normal(0.0, 0.3, 2)
    n = 12
    pts = []
    for i in range(n):
        u = 2 * math.pi * i / n
        r = 2.0 + sum(a[k] * math.cos((k + 2) * u + b[k]) for k in range(3))
        z = 2.4 + c[0] * math.sin(u) + c[1] * math.cos(2 * u)
        pts.append([round(float(r * math.cos(u)), 4), round(float(0.8 * r * math.sin(u)), 4), round(float(z), 4)])
    return pts


PATHS: dict[str, tuple[list[list[float]], bool]] = {
    "figure8-tilted": (tilted_figure_eight(), True),
    "helix": (helix(), False),
    "racetrack": (racetrack(), True),
    "random": (random_closed(), True),
}


def write_config(directory: FsPath, name: str, speed_m_s: float, profile_max_m_s: float | None = None,
                 extra: dict[str, Any] | None = None, scale: float = 1.0) -> FsPath:  # fmt: skip
    """A config with only the path and the speed (and a speed profile's max speed when given);
    ``scale`` stretches the path horizontally."""
    pts, closed = PATHS[name]
    pts = [[p[0] * scale, p[1] * scale, p[2]] for p in pts]
    data: dict[str, Any] = {"path": {"closed": closed, "waypoints": pts}, "speed_m_s": speed_m_s}
    if profile_max_m_s is not None:
        data["speed_profile"] = {"max_speed_m_s": profile_max_m_s}
    if extra:
        data.update(extra)
    out = directory / f"{name}-{speed_m_s:g}{'-p' if profile_max_m_s else ''}{f'-x{scale:g}' if scale != 1.0 else ''}.yaml"
    out.write_text(yaml.safe_dump(data))
    return out
