"""Closed-loop ``sim`` flights measured as issue 8 measures them: from activation + 8 s."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from pf_offboard.logs.steplog import StepRecord
from pf_offboard.control.adaptive import ResponseIdentifier
from pf_offboard.sim import SimSpec, simulate

ROOT = Path(__file__).resolve().parents[2]
PX4_SIH = ROOT / "configs" / "px4-sih.yaml"
SETTLE_S = 8.0  # the window starts this long after activation, as on the real SITLs


def late_records(records: Sequence[StepRecord], settle_s: float = SETTLE_S) -> list[StepRecord]:
    """The following records from activation + ``settle_s`` on."""
    recs = [r for r in records if r.mode == "following"]
    return [r for r in recs if r.time_s > recs[0].time_s + settle_s]


def errors(late: Sequence[StepRecord]) -> tuple[np.ndarray, np.ndarray]:
    """(cross-track m, speed error m/s) samples."""
    return np.array([r.cross_track_m for r in late]), np.array([r.eta2_m_s - r.speed_ref_m_s for r in late])


def fly_px4_sih(tmp: Path, name: str, edit: Callable[[dict[str, Any]], None], spec: SimSpec) -> list[StepRecord]:
    """Fly the shipped ``px4-sih.yaml`` after ``edit`` (in place, on its parsed YAML); late records."""
    data = yaml.safe_load(PX4_SIH.read_text())
    edit(data)
    config = tmp / f"{name}.yaml"
    config.write_text(yaml.safe_dump(data))
    late = late_records(simulate(config, spec, tmp / name).records)
    assert len(late) > 500
    return late


# A bad adoption forced through the identifier (the rollback guard's tests, scalar and batch)
FORCED_AFTER_S = 3.0
FORCED_DELAY_S = 0.25  # the joint candidate forced in


def force_adoption(monkeypatch: Any, gain: float, drag: float, after_s: float = FORCED_AFTER_S) -> None:
    """Make the identifier adopt its joint candidate at FORCED_DELAY_S with ``gain`` and ``drag``
    ``after_s`` after its first step, once (unless the guard rejected it)."""
    update, fit = ResponseIdentifier.update, ResponseIdentifier.fit

    def forced(self: ResponseIdentifier) -> int:
        return next(k for k in self.joint if abs(self.candidate(k)[1] - FORCED_DELAY_S) < 1e-9)

    def _update(self: ResponseIdentifier, time_s: float, velocity: Any, pieces: Any) -> Any:
        out = update(self, time_s, velocity, pieces)
        t0 = self.__dict__.setdefault("_forced_t0", time_s)
        k = forced(self)
        if time_s - t0 > after_s and not self.__dict__.get("_forced") and k not in self.rejected:
            self.__dict__["_forced"] = True
            self.active = k
            return self.candidate(k)
        return out

    def _fit(self: ResponseIdentifier, k: int) -> tuple[float, float, float, float]:
        lag, delay, g, c = fit(self, k)
        return (lag, delay, gain, drag) if k == forced(self) else (lag, delay, g, c)

    monkeypatch.setattr(ResponseIdentifier, "update", _update)
    monkeypatch.setattr(ResponseIdentifier, "fit", _fit)


