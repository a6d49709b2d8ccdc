"""``sim --push T,DURATION,AX,AY[,AZ]``: parsing, validation (exit 2 naming the flag) and the push
reaching the mock in NED at the right time."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from pf_offboard.cli import main
from pf_offboard.errors import InputError
from pf_offboard.sim import SimSpec, simulate
from pf_offboard.sim.flight import parse_push

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "configs" / "paper.yaml"


def test_push_flag_parses_enu() -> None:
    assert parse_push("8,0.5,-10,0") == (8.0, 0.5, -10.0, 0.0, 0.0)
    assert parse_push("1,0.25,3,4,-1") == (1.0, 0.25, 3.0, 4.0, -1.0)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("8,0.5,-10", "--push: expected T,DURATION,AX,AY[,AZ]"),
        ("8,x,1,1", "--push: expected T,DURATION,AX,AY[,AZ]"),
        ("-1,0.5,1,0", "--push: start T must be >= 0 s"),
        ("1,0,1,0", "--push: DURATION must be in [0.001, 10] s"),
        ("1,0.5,40,40", "--push: acceleration must be <= 50 m/s^2"),
        ("1,0.5,nan,0", "--push: must be 5 finite numbers"),
    ],
)
def test_bad_push_exits_2(tmp_path: Path, text: str, message: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(InputError):
        parse_push(text)
    assert main(["sim", "--config", str(PAPER), "--out", str(tmp_path), f"--push={text}"]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "flight.tlog").exists()


def test_push_reaches_the_mock_in_ned(tmp_path: Path) -> None:
    """An east push (ENU x) is a NED y push: the same flight until it starts, then shoved east."""
    spec = SimSpec(vehicle="fast", start_enu_m=(0.0, -1.5, 2.0), rate_hz=50.0, duration_s=0.6, epoch_unix_s=1.78e9)
    free = simulate(PAPER, spec, tmp_path / "free").records
    pushed = simulate(PAPER, replace(spec, push=(0.2, 0.3, 8.0, 0.0, 0.0)), tmp_path / "pushed").records
    for a, b in zip(free, pushed):
        dv = [b.velocity_enu_m_s[i] - a.velocity_enu_m_s[i] for i in range(3)]
        if a.time_s <= 0.2:
            assert dv == [0.0, 0.0, 0.0]
        elif a.time_s <= 0.3:  # 8 m/s^2 east, before the controller's (lagged) reaction
            assert dv[0] == pytest.approx(8.0 * (a.time_s - 0.2), rel=0.1)
            assert abs(dv[1]) < 0.1 * dv[0] and abs(dv[2]) < 0.1 * dv[0]
    with pytest.raises(InputError) as exc:
        simulate(PAPER, SimSpec(vehicle="fast", push=(0.0, 99.0, 1.0, 0.0, 0.0), duration_s=0.1), tmp_path / "bad")
    assert exc.value.field == "--push"
