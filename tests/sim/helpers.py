"""Closed-loop ``sim`` flights measured as issue 8 measures them: from activation + 8 s."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from pf_offboard.logs.steplog import StepRecord
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
