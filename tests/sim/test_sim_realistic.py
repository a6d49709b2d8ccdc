"""``pf-offboard sim`` with the realistic presets and wind: flags, frames, errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pf_offboard.cli import main
from pf_offboard.errors import InputError
from pf_offboard.sim import SimSpec, simulate
from pf_offboard.sim.flight import parse_gusts, parse_wind
from sitl_mock.dynamics import PRESET_NAMES

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "configs" / "paper.yaml"


def test_wind_flag_parses_enu() -> None:
    assert parse_wind("3,1") == (3.0, 1.0, 0.0)
    assert parse_wind("3,1,-0.5") == (3.0, 1.0, -0.5)
    assert parse_gusts("0.5") == (0.5, 2.0)
    assert parse_gusts("0.5,4") == (0.5, 4.0)


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--wind", "3"], "--wind: expected E,N or E,N,U"),
        (["--wind", "x,1"], "--wind: expected E,N or E,N,U"),
        (["--wind", "inf,0"], "--wind: values must be 3 finite numbers"),
        (["--wind", "30,0"], "--wind: wind speed must be <= 20 m/s"),
        (["--wind-gusts", "-0.1"], "--wind-gusts: std must be in [0, 10] m/s"),
        (["--wind-gusts", "1,0.01"], "--wind-gusts: time constant must be in [0.05, 600] s"),
    ],
)
def test_bad_wind_and_vehicle_exit_2(tmp_path: Path, flags: list[str], message: str,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "--config", str(PAPER), "--out", str(tmp_path), *flags]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "flight.tlog").exists()


def test_unknown_vehicle_is_an_argparse_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["sim", "--config", str(PAPER), "--out", str(tmp_path), "--vehicle", "x500"])
    assert exc.value.code == 2 and "invalid choice" in capsys.readouterr().err


def test_wind_reaches_the_mock_in_ned(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """An east wind (ENU x) is a NED y wind in the mock; gusts are on."""
    seen = {}
    from sitl_mock import autopilot as autopilot_module

    original = autopilot_module.Autopilot.__init__

    def spy(self, config, rng=None):  # type: ignore[no-untyped-def]
        original(self, config, rng)
        seen["config"] = config
        seen["ap"] = self

    monkeypatch.setattr(autopilot_module.Autopilot, "__init__", spy)
    spec = SimSpec(vehicle="px4-sih", wind_enu_m_s=(3.0, 0.0, 0.0), wind_gusts=(0.3, 2.0), duration_s=1.0, seed=1)
    result = simulate(PAPER, spec, tmp_path)
    assert not result.crashed
    config = seen["config"]
    np.testing.assert_allclose(config.wind_ned_m_s, (0.0, 3.0, 0.0), atol=1e-12)
    assert (config.wind_gust_std_m_s, config.wind_gust_time_constant_s, config.vehicle) == (0.3, 2.0, "px4-sih")
    assert 1.5 < seen["ap"].truth.wind_ned_m_s[1] < 4.5


@pytest.mark.parametrize("vehicle", PRESET_NAMES)
def test_every_preset_flies_a_short_sim(tmp_path: Path, vehicle: str) -> None:
    autopilot = "ardupilot" if vehicle == "arducopter" else "px4"
    result = simulate(PAPER, SimSpec(vehicle=vehicle, autopilot=autopilot, duration_s=2.0, rate_hz=50.0), tmp_path)
    assert not result.crashed and result.sim_time_s == pytest.approx(2.0, abs=0.05)


def test_spec_rejects_bad_wind() -> None:
    with pytest.raises(InputError, match="--wind"):
        simulate(PAPER, SimSpec(vehicle="fast", wind_enu_m_s=(float("nan"), 0.0, 0.0)), "/nonexistent")
