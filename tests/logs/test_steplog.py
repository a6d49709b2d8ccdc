"""Step-log CSV: exact float round trip, header, and errors naming row and column."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from pf_offboard.logs.steplog import COLUMNS, StepLogWriter, StepRecord, column, read_steplog
from pf_offboard.logs.tlog import LogError


def make_record(rng: np.random.Generator, t: float, event: str = "") -> StepRecord:
    v = rng.normal(size=30)
    q = rng.normal(size=4)
    return StepRecord(
        time_s=t, mode="following", active=True,
        position_enu_m=v[0:3], velocity_enu_m_s=v[3:6], lam=v[6], eta1_m=v[7], eta2_m_s=v[8],
        xi1_m=v[9], xi2_m_s=v[10], phi1_m=v[11], phi2_m_s=v[12], cross_track_m=abs(v[13]),
        speed_ref_m_s=-1.5, accel_cmd_enu_m_s2=v[14:17], thrust_cmd_m_s2=9.81 + v[17],
        q_cmd_enu_flu=q / np.linalg.norm(q), rates_cmd_flu_rad_s=v[18:21], yaw_cmd_rad=v[21],
        yaw_rate_cmd_rad_s=v[22], sat_tangential=bool(v[23] > 0), sat_transversal=False,
        sat_tilt=True, sat_thrust=False, sat_approach_speed=bool(v[24] > 0), event=event,
    )


def test_exact_round_trip(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    recs = [make_record(rng, 0.004 * i, event="activated, \"quoted\"" if i == 3 else "") for i in range(50)]
    nan_rec = StepRecord(**{**recs[0].__dict__, "accel_cmd_enu_m_s2": (math.nan,) * 3, "active": False})
    recs.append(nan_rec)
    with StepLogWriter.open(tmp_path / "s.csv") as w:
        w.write_all(recs)
    back = read_steplog(tmp_path / "s.csv")
    assert back[:50] == recs[:50]  # bit-identical floats
    assert back[3].event == "activated, \"quoted\""
    assert all(math.isnan(x) for x in back[50].accel_cmd_enu_m_s2) and not back[50].active
    assert (tmp_path / "s.csv").read_text().splitlines()[0].split(",") == list(COLUMNS)
    assert column(back, "position_enu_m").shape == (51, 3)
    assert column(back, "eta2_m_s").shape == (51,)


def test_vector_size_checked() -> None:
    rng = np.random.default_rng(2)
    rec = make_record(rng, 0.0)
    with pytest.raises(ValueError, match="position_enu_m: expected 3"):
        StepRecord(**{**rec.__dict__, "position_enu_m": (1.0, 2.0)})


def test_errors_name_row_and_column(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    with StepLogWriter.open(tmp_path / "s.csv") as w:
        w.write_all(make_record(rng, 0.004 * i) for i in range(5))
    lines = (tmp_path / "s.csv").read_text().splitlines()
    bad = lines[3].split(",")
    bad[COLUMNS.index("xi1_m")] = "abc"
    (tmp_path / "b.csv").write_text("\n".join([*lines[:3], ",".join(bad), *lines[4:]]) + "\n")
    with pytest.raises(LogError, match=r"row 4: column 'xi1_m': not a number: 'abc'"):
        read_steplog(tmp_path / "b.csv")
    (tmp_path / "t.csv").write_text("\n".join(lines) + "\n" + lines[2][:40] + "\n")
    with pytest.raises(LogError, match=r"row 7: expected 37 cells"):
        read_steplog(tmp_path / "t.csv")
    (tmp_path / "h.csv").write_text("a,b,c\n1,2,3\n")
    with pytest.raises(LogError, match=r"row 1: not a pf-offboard step-log header"):
        read_steplog(tmp_path / "h.csv")
    (tmp_path / "x.csv").write_bytes(b"\xff\xfe\x00")
    with pytest.raises(LogError, match=r"byte 0: not UTF-8"):
        read_steplog(tmp_path / "x.csv")
