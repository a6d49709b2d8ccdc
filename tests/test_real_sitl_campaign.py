"""scripts/real_sitl_campaign.py's plan of flights (no SITL flown): ``--delay-step`` gives each
repeat its own start delay (PX4 SIH's noise is seeded with a constant), the same for every config."""

from __future__ import annotations

from pathlib import Path

import pytest


def test_each_repeat_starts_later_by_the_step_and_configs_share_the_delays(tmp_path: Path, script) -> None:
    c = script("real_sitl_campaign")
    args = c.build_parser().parse_args(["--out", str(tmp_path), "--autopilots", "px4", "--paths", "figure8-tilted,helix",
                                        "--outputs", "acceleration,attitude", "--speeds", "1.5", "--repeat", "3",
                                        "--delay-step", "3.7"])  # fmt: skip
    specs = c.flight_specs(args)
    assert len(specs) == 3 * 2 * 2
    by_repeat: dict[str, set[float]] = {}
    for s in specs:
        rep = s["workdir"].rsplit("-", 1)[1]
        by_repeat.setdefault(rep, set()).add(s["start_delay_s"])
    assert by_repeat == {"0": {0.0}, "1": {3.7}, "2": {7.4}}  # every config and output of a repeat alike


def test_without_a_step_every_flight_starts_at_once(tmp_path: Path, script) -> None:
    c = script("real_sitl_campaign")
    args = c.build_parser().parse_args(["--out", str(tmp_path), "--autopilots", "px4,arducopter", "--repeat", "2"])
    assert {s["start_delay_s"] for s in c.flight_specs(args)} == {0.0}


@pytest.mark.parametrize("step", ["-1", "nan", "inf"])
def test_a_negative_or_non_finite_step_is_refused_with_exit_2(tmp_path: Path, step: str, capsys, script) -> None:
    c = script("real_sitl_campaign")
    with pytest.raises(SystemExit) as exc:
        c.main(["--out", str(tmp_path / "out"), "--delay-step", step])
    assert exc.value.code == 2
    assert "--delay-step" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()  # nothing flown, nothing written
