"""A 2 s telemetry blackout in `rates` mode: no open-loop rates, the vehicle stays level and holds
its height, and ends in the hold mode the app requested (confirmed once telemetry returns).

Before issue 9 the keep-alive re-sent the last body rates for the 0.5 s before the stale-state
timeout: 90-100 deg of tilt and 1.2-1.4 m of height lost on both profiles."""

from __future__ import annotations

import numpy as np
import pytest
from sitl_mock.runner import spawn

from app.flights import run_fly

from .common import entries, hover, last_heartbeat_mode, is_mode_request, is_safe_setpoint, own_clock, read_truth, write_config

pytestmark = pytest.mark.integration

# Vehicle time from the first entry into OFFBOARD / GUIDED (the mock's windows_from_offboard): the
# blackout falls 3 s into following however long the app took to start.
BLACKOUT_S = (3.0, 5.0)
MAX_TILT_DEG = 60.0  # safety.max_tilt_deg (the default); the core's own limit is 50 deg (paper.yaml)


@pytest.mark.parametrize("profile", ["px4", "ardupilot"])
def test_blackout_in_rates_mode_stays_level_and_holds_height(tmp_path, profile: str) -> None:
    config = write_config(tmp_path, safety={"max_tilt_deg": MAX_TILT_DEG}, output_mode="rates")
    truth_log = tmp_path / "truth.csv"
    flags = ["--airborne", "--output", "rates", "--duration", "30"]
    if profile == "ardupilot":
        flags.append("--set-guid-options")
    with spawn(own_clock(profile, hover(), truth_log, blackout_s=BLACKOUT_S, windows_from_offboard=True)) as mock:
        outcome = run_fly(mock.ports.udp, config, tmp_path / "log", *flags)
    truth = read_truth(truth_log)
    hold = "AUTO.LOITER" if profile == "px4" else "BRAKE"
    offboard = "OFFBOARD" if profile == "px4" else "GUIDED"
    t_offboard = float(truth.time_s[truth.mode.index(offboard)])
    t0, t1 = t_offboard + BLACKOUT_S[0], t_offboard + BLACKOUT_S[1]
    window = (truth.time_s >= t0) & (truth.time_s <= t1 + 1.0)
    z_up = -truth.position_ned_m[:, 2]
    z_at_blackout = float(np.interp(t0, truth.time_s, z_up))
    height_lost = z_at_blackout - float(z_up[window].min())
    tilt = float(truth.tilt_deg[window].max())
    print(f"\n{profile} rates, blackout {t0:.2f}..{t1:.2f} s: max tilt {tilt:.1f} deg, height lost {height_lost:.3f} m; "
          f"end mode {last_heartbeat_mode(tmp_path / 'log', profile)}, armed {truth.armed[-1]}; app: {outcome.reason} (exit {outcome.exit_code})")  # fmt: skip
    assert outcome.exit_code == 3, outcome.reason
    assert "state went stale" in outcome.reason and f"{hold} requested, confirmed" in outcome.reason
    assert tilt <= MAX_TILT_DEG
    assert height_lost <= 0.3
    assert last_heartbeat_mode(tmp_path / "log", profile) == hold and truth.armed[-1] and not truth.landed[-1]
    assert "AUTO.RTL" not in truth.mode and "RTL" not in truth.mode
    # from the app's side: no body-rate setpoint left after the last state sample before the
    # blackout (beyond the one computed from it), only safe setpoints and the hold request
    log = entries(tmp_path / "log")
    states = [e for e in log if e.direction == "in" and e.message.get_type() == "LOCAL_POSITION_NED"]
    last_state = max(e.time_unix_s for e in states if e.message.time_boot_ms < t0 * 1000)
    late = [e.message for e in log if e.direction == "out" and e.time_unix_s > last_state + 0.05]
    late_commands = [m for m in late if m.get_type() in ("SET_ATTITUDE_TARGET", "SET_POSITION_TARGET_LOCAL_NED", "COMMAND_LONG")]
    resumed = [m for m in late_commands if m.get_type() == "SET_ATTITUDE_TARGET" and m.time_boot_ms > t1 * 1000]
    assert late_commands and not resumed  # following never resumed after the stale timeout
    assert all(is_safe_setpoint(m) or is_mode_request(m) for m in late_commands), {m.type_mask for m in late_commands if m.get_type() == "SET_ATTITUDE_TARGET"}
