"""Issue 8's targets on the real autopilots in SITL, when one is built on this machine (opt-in).

Skipped unless an environment variable points at a SITL build (CI has none, and stays green):

- ``PF_OFFBOARD_PX4_SITL``: PX4's ``build/px4_sitl_default`` directory (``bin/px4`` and ``rootfs``),
  built as ``../shared/notes/px4-sitl.md`` says. Each test boots a fresh SIH quadrotor (airframe
  10040): it deletes ``parameters.bson``, ``parameters_backup.bson`` and ``dataman`` in that
  ``rootfs``, as the notes do.
- ``PF_OFFBOARD_ARDUCOPTER``: ArduPilot's ``build/sitl/bin/arducopter`` (its ``copter.parm`` is found
  beside the source tree), built as ``../shared/notes/ardupilot-sitl.md`` says.

Each flight is ``pf-offboard fly --takeoff 2`` with the shipped config for that autopilot, as a user
runs it, measured from activation + 8 s on the autopilot's estimate. Targets: cross-track RMS
<= 5 cm, speed error RMS <= 5 cm/s, |mean| <= 2 cm/s. PX4 SIH flies five laps, judged against them
over all five (2026-11-27: 3.4-4.1 cm, 3.7-4.6 cm/s in six flights). Its first two laps (the window
of a ``--laps 2`` flight, 13 s) depend on which stretch of EKF2's noise they see: 25 such windows on
2026-11-27 flew 3.3-5.04 cm and 3.5-5.12 cm/s (mean 4.2 cm/s), two of them 0.07-0.12 cm/s over
the speed target and one 0.04 cm over the cross-track one (README, docs/controller.md *The floor*),
so that window is held to the targets plus 10 % (a regression check, not the target). ArduCopter
flies two laps (1.3-1.4 cm, 1.0-1.1 cm/s). These run on the wall clock (the autopilots' own speed
factor 1): about 1.5 min each.
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import subprocess
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from pf_offboard.app.fly import add_arguments, fly
from pf_offboard.logs.steplog import read_steplog

pytestmark = pytest.mark.real_sitl

REPO = Path(__file__).resolve().parents[2]
PX4_BUILD = os.environ.get("PF_OFFBOARD_PX4_SITL")
ARDUCOPTER = os.environ.get("PF_OFFBOARD_ARDUCOPTER")
SETTLE_S = 8.0


def _figures(log_dir: Path, laps: float | None = None) -> tuple[float, float, float]:
    """(cross-track RMS m, speed error RMS m/s, mean speed error m/s) from activation + 8 s, to the
    end of the flight or (``laps``) to where that many laps of net progress were done: the window
    a ``--laps`` flight of that many laps measures."""
    recs = [r for r in read_steplog(log_dir / "flight.csv") if r.mode == "following"]
    if laps is not None:
        recs = recs[: _laps_done_index(np.array([r.eta1_m for r in recs]), laps)]
    late = [r for r in recs if r.time_s >= recs[0].time_s + SETTLE_S]
    assert late and late[-1].time_s - late[0].time_s > 10.0, "too short a flight to measure"
    ct = np.array([r.cross_track_m for r in late])
    err = np.array([r.eta2_m_s - r.speed_ref_m_s for r in late])
    return float(np.sqrt(np.mean(ct**2))), float(np.sqrt(np.mean(err**2))), float(np.mean(err))


def _laps_done_index(eta1_m: np.ndarray, laps: float) -> int:
    """Index of the first sample after ``laps`` laps of net progress along a closed path (its
    arclength wraps at the path's length, taken as the span the flight covered)."""
    length = float(eta1_m.max() - eta1_m.min())
    step = np.diff(eta1_m)
    step[step > 0.5 * length] -= length  # a wrap, either way round
    step[step < -0.5 * length] += length
    progress = np.abs(np.concatenate(([0.0], np.cumsum(step))))
    done = np.flatnonzero(progress >= laps * length)
    assert len(done), f"fewer than {laps} laps flown"
    return int(done[0])


def _fly(log_dir: Path, connect: str, config: str, laps: int, *flags: str) -> tuple[float, float, float]:
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(["--connect", connect, "--config", str(REPO / "configs" / f"{config}.yaml"), "--takeoff", "2",
                              "--laps", str(laps), "--log-dir", str(log_dir), "--quiet", *flags])  # fmt: skip
    outcome = fly(args)
    assert outcome.exit_code == 0, outcome.reason
    return _figures(log_dir)


@contextmanager
def _running(command: list[str], cwd: Path, log: Path) -> Iterator[None]:
    """A SITL process in its own session (it is stopped with SIGTERM, then SIGKILL)."""
    with log.open("w") as out:
        # a shell stays its parent: ArduCopter SITL exits when its parent process does
        proc = subprocess.Popen(["bash", "-c", " ".join(command) + "; true"], cwd=cwd, stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True, env={**os.environ, **_px4_env()})  # fmt: skip
        try:
            yield
        finally:
            os.killpg(proc.pid, signal.SIGTERM)
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()


def _wait_until_free(port: int, timeout_s: float = 90.0) -> None:
    """Wait until TCP ``port`` can be bound. ArduCopter SITL binds it without SO_REUSEADDR: right
    after the previous case's SITL the port can still be held (TIME_WAIT lasts up to 60 s), the new
    SITL then logs "bind failed on port 5760 - Address already in use" and the app finds nothing
    listening (seen once in s44's run: the `rates` case after `attitude`)."""
    deadline = time.monotonic() + timeout_s
    while True:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
            try:
                probe.bind(("0.0.0.0", port))
                return
            except OSError:
                if time.monotonic() > deadline:
                    raise AssertionError(f"TCP port {port} still in use after {timeout_s:.0f} s") from None
        time.sleep(0.5)


def _px4_env() -> dict[str, str]:
    return {"PX4_SIMULATOR": "sihsim", "PX4_SIM_MODEL": "sihsim_quadx", "HEADLESS": "1", "PX4_SIM_SPEED_FACTOR": "1"}


def _check(ct: float, rms: float, mean: float, what: str, margin: float = 1.0) -> None:
    """Issue 8's targets (``margin`` > 1: that much above them, for a window EKF2's noise decides)."""
    print(f"\n{what}: cross-track {100 * ct:.2f} cm, speed error {100 * rms:.2f} cm/s (mean {100 * mean:+.2f})")
    assert ct <= 0.05 * margin and rms <= 0.05 * margin and abs(mean) <= 0.02


@pytest.mark.skipif(PX4_BUILD is None, reason="set PF_OFFBOARD_PX4_SITL to PX4's build/px4_sitl_default to fly the real PX4 SIH")
@pytest.mark.parametrize("output", ["acceleration", "attitude", "rates"])
def test_px4_sih_meets_issue_8s_targets(tmp_path: Path, output: str) -> None:
    build = Path(str(PX4_BUILD))
    rootfs = build / "rootfs"
    assert (build / "bin" / "px4").exists(), f"no bin/px4 in {build}"
    for name in ("parameters.bson", "parameters_backup.bson", "dataman"):  # a fresh vehicle
        (rootfs / name).unlink(missing_ok=True)
    with _running(["../bin/px4", "-d"], rootfs, tmp_path / "px4.log"):
        figures = _fly(tmp_path / "log", "udpin:127.0.0.1:14540", "px4-sih", 5, "--output", output)
    _check(*figures, f"PX4 SIH, {output}, five laps")
    _check(*_figures(tmp_path / "log", laps=2), f"PX4 SIH, {output}, its first two laps", margin=1.1)
    _check_identify(tmp_path / "log" / "flight.tlog", output)


def _check_identify(tlog: Path, output: str) -> None:
    """identify on the flight's own log finds SIH's physical drag (SIH_KDV 1 N/(m/s) on 1 kg:
    1.0 1/s) within 10 %: horizontally with the velocity made position-consistent as the app flew
    it (five-lap flights: 1.01-1.07; EKF2's horizontal velocity is biased, as reported 0.91-0.96),
    vertically as reported within 15 % (0.875-1.03 over ten five-lap flights, 0.875-0.93 in four of
    the six of 2026-11-27; EKF2's vertical velocity is not biased like its horizontal one,
    and the correction adds the height estimate's wander: 1.02-1.21). The vertical is fitted
    along the measured tilt and answers before the horizontal (not comparable in a rates log, whose
    horizontal fit is the thrust path's)."""
    from pf_offboard.identify import identify, load_log

    ident = identify(load_log(tlog, velocity_correction_s=0.3).segments)
    z_reported = identify(load_log(tlog).segments).z
    xy, z = ident.xy, ident.z
    print(f"identify ({output}): xy rise {xy.rise_63_s:.3f} s gain {xy.gain:.3f} drag {xy.drag_1_s:.3f}; "
          f"z rise {z.rise_63_s:.3f} s gain {z.gain:.3f} drag {z.drag_1_s:.3f} (tilt {z.measured_tilt_share:.2f}); "
          f"z as reported: drag {z_reported.drag_1_s:.3f}")  # fmt: skip
    assert z.measured_tilt_share == 1.0
    assert xy.drag_1_s == pytest.approx(1.0, rel=0.10)
    assert z_reported.drag_1_s == pytest.approx(1.0, rel=0.15)
    assert xy.r2 > 0.85 and z.r2 > 0.85
    if output != "rates":
        assert z.rise_63_s < xy.rise_63_s


@pytest.mark.skipif(ARDUCOPTER is None, reason="set PF_OFFBOARD_ARDUCOPTER to ArduPilot's build/sitl/bin/arducopter to fly ArduCopter SITL")
@pytest.mark.parametrize("output", ["attitude", "rates"])
def test_arducopter_meets_issue_8s_targets(tmp_path: Path, output: str) -> None:
    binary = Path(str(ARDUCOPTER))
    params = binary.parents[3] / "Tools" / "autotest" / "default_params" / "copter.parm"
    assert binary.exists() and params.exists(), f"no {binary} or {params}"
    command = [str(binary), "--model", "+", "--speedup", "1", "--defaults", str(params), "-I0",
               "--home", "-35.363261,149.165230,584,353", "-w"]  # fmt: skip
    _wait_until_free(5760)
    with _running(command, tmp_path, tmp_path / "arducopter.log"):
        figures = _fly(tmp_path / "log", "tcp:127.0.0.1:5760", "arducopter", 2, "--output", output, "--set-guid-options")
    _check(*figures, f"ArduCopter SITL, {output}, two laps")
