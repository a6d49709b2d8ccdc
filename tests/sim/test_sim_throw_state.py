"""``sim`` thrown starts with an attitude, body rates and an engagement time; flights without logs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pf_offboard import frames
from pf_offboard.cli import main
from pf_offboard.errors import InputError
from pf_offboard.sim import SimSpec, simulate
from pf_offboard.sim.flight import SimFlight, parse_quaternion

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "configs" / "paper.yaml"
Q_ENU_FLU = (0.9, 0.3, -0.2, 0.2449489742783178)  # unit: 0.81 + 0.09 + 0.04 + 0.06
THROW = (0.5, -1.5, 4.0, 1.0, 0.0, 0.5)


def test_attitude_and_rates_reach_the_mock_in_ned_frd(tmp_path: Path) -> None:
    spec = SimSpec(vehicle="fast", throw_enu=THROW, throw_q_enu_flu=Q_ENU_FLU, throw_body_rates_flu_rad_s=(1.0, 2.0, -0.5), duration_s=0.05)
    flight = SimFlight(PAPER, spec, tmp_path, write_logs=False)
    truth = flight.autopilot.truth
    np.testing.assert_allclose(truth.q_ned_frd, frames.quat_enu_flu_to_ned_frd(Q_ENU_FLU), atol=1e-12)
    np.testing.assert_allclose(truth.rates_frd_rad_s, (1.0, -2.0, 0.5), atol=1e-12)
    np.testing.assert_allclose(frames.quat_ned_frd_to_enu_flu(truth.q_ned_frd), Q_ENU_FLU, atol=1e-12)


def test_engage_at_once_or_after_a_delay_without_files(tmp_path: Path) -> None:
    at_once = simulate(PAPER, SimSpec(vehicle="fast", throw_enu=THROW, throw_engage_after_s=0.0, duration_s=0.5, rate_hz=50.0), tmp_path,
                       write_logs=False)  # fmt: skip
    later = simulate(PAPER, SimSpec(vehicle="fast", throw_enu=THROW, throw_engage_after_s=0.3, duration_s=0.5, rate_hz=50.0), tmp_path,
                     write_logs=False)  # fmt: skip
    assert at_once.activation_time_s == pytest.approx(0.0, abs=0.021)
    assert later.activation_time_s == pytest.approx(0.3, abs=0.021)
    assert not at_once.crashed and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(("kwargs", "flag"), [
    ({"throw_q_enu_flu": Q_ENU_FLU}, "--throw-attitude"),  # no --throw
    ({"throw_enu": THROW, "throw_q_enu_flu": (1.0, 1.0, 0.0, 0.0)}, "--throw-attitude"),
    ({"throw_enu": THROW, "throw_body_rates_flu_rad_s": (40.0, 0.0, 0.0)}, "--throw-rates"),
    ({"throw_enu": THROW, "throw_body_rates_flu_rad_s": (float("nan"), 0.0, 0.0)}, "--throw-rates"),
    ({"throw_enu": THROW, "throw_engage_after_s": -1.0}, "--throw-engage-after"),
    ({"throw_enu": THROW, "throw_engage_after_s": 0.0, "throw_height_m": 2.0}, "--throw-engage-after"),
])
def test_bad_throw_state_names_the_flag(tmp_path: Path, kwargs: dict[str, object], flag: str) -> None:
    with pytest.raises(InputError) as exc:
        simulate(PAPER, SimSpec(**kwargs), tmp_path)  # type: ignore[arg-type]
    assert exc.value.field == flag
    assert list(tmp_path.iterdir()) == []


def test_cli_flags(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert parse_quaternion("1,0,0,0.0001") == pytest.approx((1.0, 0.0, 0.0, 0.0001), abs=1e-8)
    base = ["sim", "--config", str(PAPER), "--out", str(tmp_path), "--throw", "0,0,4,0,0,0"]
    assert main([*base, "--throw-attitude", "1,1,0,0"]) == 2
    assert "--throw-attitude: must be a unit quaternion w,x,y,z, got norm 1.41421" in capsys.readouterr().err
    assert main(["sim", "--config", str(PAPER), "--out", str(tmp_path), "--throw-rates", "1,0,0"]) == 2
    assert "--throw-rates: only a thrown start (--throw) takes it" in capsys.readouterr().err
