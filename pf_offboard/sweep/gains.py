"""Gain sweep: candidate (bandwidth, damping) pairs, the configs that fly them, and their ranking.

A candidate sets both loops (transversal and tangential) to its bandwidth and damping, as
``gains: auto`` does. Every candidate flies the same starts (flight ``i`` is drawn from
``(seed, i)`` whatever the candidate), so the ranking compares gains, not luck. Random candidates
come from their own child of the seed (``SeedSequence(seed, spawn_key=(2**32,))``), apart from
every flight's.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from pf_offboard.errors import InputError
from pf_offboard.sweep.starts import GAINS_SPAWN_KEY

MAX_CANDIDATES = 400
BANDWIDTH_HZ = (0.01, 50.0)  # the config loader's range (pf_offboard.config)
DAMPING = (0.01, 5.0)


@dataclass(frozen=True)
class GainCandidate:
    """One (bandwidth, damping) pair to fly, for both loops."""

    id: int
    bandwidth_hz: float
    damping: float

    def columns(self) -> dict[str, Any]:
        return {"gains_id": self.id, "bandwidth_hz": self.bandwidth_hz, "damping": self.damping}


def parse_range(text: str, flag: str, bounds: tuple[float, float]) -> tuple[float, float]:
    """``LO:HI`` (or one value ``V``, i.e. ``V:V``) within ``bounds``."""
    parts = text.split(":")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise InputError(flag, f"expected LO:HI or a single number, got {text!r}") from None
    if len(values) not in (1, 2):
        raise InputError(flag, f"expected LO:HI or a single number, got {text!r}")
    lo, hi = values[0], values[-1]
    if not (math.isfinite(lo) and math.isfinite(hi) and bounds[0] <= lo <= hi <= bounds[1]):
        raise InputError(flag, f"need {bounds[0]:g} <= LO <= HI <= {bounds[1]:g}, got {text!r}")
    return lo, hi


def candidates(mode: str, bandwidth_hz: tuple[float, float], damping: tuple[float, float], points: int,
               seed: int) -> list[GainCandidate]:  # fmt: skip
    """``grid``: ``points`` values per axis (``points²`` candidates, bandwidth-major);
    ``random``: ``points`` candidates drawn uniformly from the box."""
    if mode not in ("grid", "random"):
        raise InputError("--gains", f"must be grid or random, got {mode!r}")
    count = points * points if mode == "grid" else points
    if not (1 <= points and count <= MAX_CANDIDATES):
        raise InputError("--gain-points", f"gives {count} candidates; need 1..{MAX_CANDIDATES}")
    if mode == "grid":
        pairs = [(float(b), float(d)) for b in np.linspace(*bandwidth_hz, points) for d in np.linspace(*damping, points)]
    else:
        rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(GAINS_SPAWN_KEY,)))
        pairs = [(float(rng.uniform(*bandwidth_hz)), float(rng.uniform(*damping))) for _ in range(points)]
    return [GainCandidate(i, b, d) for i, (b, d) in enumerate(pairs)]


def with_gains(data: Mapping[str, Any], candidate: GainCandidate) -> dict[str, Any]:
    """A copy of a config's YAML mapping flying ``candidate`` in both loops."""
    loop = {"bandwidth_hz": candidate.bandwidth_hz, "damping": candidate.damping}
    out = dict(data)
    out["gains"] = {"transversal": dict(loop), "tangential": dict(loop)}
    return out


def rank(rows: Sequence[Mapping[str, Any]], cands: Sequence[GainCandidate]) -> list[dict[str, Any]]:
    """One line per candidate, best first: highest success rate, then the shortest 90th-percentile
    time to be caught over all its flights (a failed flight counts as never caught: inf), then
    the shortest median, then the tightest tracking after being caught."""
    out = []
    for c in cands:
        mine = [r for r in rows if r["gains_id"] == c.id]
        ok = sum(bool(r["success"]) for r in mine)
        times = [r["caught_time_s"] if r["success"] else math.inf for r in mine]
        p50, p90 = (float(np.percentile(times, q, method="inverted_cdf")) if times else math.inf for q in (50, 90))
        rms = [r["cross_track_rms_after_m"] for r in mine if r["success"]]
        out.append({
            **c.columns(),
            "flights": len(mine),
            "success_rate": ok / len(mine) if mine else 0.0,
            "caught_p50_s": p50,
            "caught_p90_s": p90,
            "cross_track_rms_after_m_mean": float(np.mean(rms)) if rms else math.nan,
        })  # fmt: skip
    out.sort(key=lambda r: (-r["success_rate"], r["caught_p90_s"], r["caught_p50_s"],
                            math.inf if math.isnan(r["cross_track_rms_after_m_mean"]) else r["cross_track_rms_after_m_mean"], r["gains_id"]))
    for i, r in enumerate(out, 1):
        r["rank"] = i
    return [{"rank": r.pop("rank"), **r} for r in out]
