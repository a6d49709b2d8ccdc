"""Fly the default config (a path and a speed) on the real autopilots in SITL and measure it.

Each flight runs in its own network namespace (``unshare -n``, loopback only) and /tmp: a fresh SITL (PX4
SIH from a private working directory, or ArduCopter SITL from a private directory), then
``pf-offboard fly --takeoff 2`` as a user runs it, then the SITL is stopped. Figures from the step
log with :mod:`pf_offboard.logs.measures` (speed along the path from the position's derivative,
the estimator's beside it; window from activation + 8 s); on PX4 also against SIH's ground truth
from the ULog PX4 wrote (:func:`pf_offboard.logs.truth.judge_truth`).

    python scripts/real_sitl_campaign.py --out runs/baseline                 # everything
    python scripts/real_sitl_campaign.py --autopilots px4 --paths helix --outputs acceleration
    python scripts/real_sitl_campaign.py --app-python /work/venvs/other/bin/python --app-path /work/wt/other

PX4 SIH seeds its sensor noise with a constant (``srand(1234)`` in sih.cpp): flights that start
alike on a quiet machine fly nearly the same noise, and repeats are then not independent samples.
``--delay-step S`` starts repeat k's app k*S s after its SITL, a stretch of the noise of its own,
about the same one for every config and output (close, not exact: the start's timing still varies).

``--app-python`` / ``--app-path`` fly another checkout's app (its ``python -m pf_offboard``) while
the measuring stays this one's. At most one PX4 and one ArduCopter fly at once.

Environment: PF_OFFBOARD_PX4_SITL (PX4's build/px4_sitl_default, default /work/sitl/px4/...),
PF_OFFBOARD_ARDUCOPTER (build/sitl/bin/arducopter, default /work/sitl/ardupilot/...).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import queue
import shlex
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
CONFIG_DIR = REPO / "tests" / "real_sitl" / "configs"
PX4_BUILD = Path(os.environ.get("PF_OFFBOARD_PX4_SITL", "/work/sitl/px4/build/px4_sitl_default"))
ARDUCOPTER = Path(os.environ.get("PF_OFFBOARD_ARDUCOPTER", "/work/sitl/ardupilot/build/sitl/bin/arducopter"))
OUTPUTS = {"px4": ("acceleration", "attitude", "rates"), "arducopter": ("attitude", "rates")}
HOME = "-35.363261,149.165230,584,353"


# ------------------------------------------------------------------------------------ SITL control
def start_sitl(autopilot: str, workdir: Path, params: dict[str, float] | None = None,
               px4_env: dict[str, str] | None = None, model: str | None = None) -> subprocess.Popen[bytes]:
    """A fresh SITL in ``workdir`` (its own session; stop with :func:`stop_sitl`); ``params``: the
    autopilot's parameters at boot (PX4: PX4_PARAM_*; ArduCopter: a defaults file after copter.parm);
    ``px4_env``: extra environment for PX4 (e.g. PX4_SIH_NOISE_SCALE, read by a SIH patched to scale
    its sensor noise); ``model``: ArduCopter SITL's frame (``--model``, default "+")."""
    workdir.mkdir(parents=True, exist_ok=True)
    log = (workdir / f"{autopilot}.log").open("wb")
    env = dict(os.environ)
    if autopilot == "px4":
        rootfs = workdir / "rootfs"
        rootfs.mkdir(exist_ok=True)
        env.update({"PX4_SIMULATOR": "sihsim", "PX4_SIM_MODEL": "sihsim_quadx", "HEADLESS": "1", "PX4_SIM_SPEED_FACTOR": "1"})
        env.update({f"PX4_PARAM_{k}": str(v) for k, v in (params or {}).items()})
        env.update(px4_env or {})
        cmd = [str(PX4_BUILD / "bin" / "px4"), "-d", "-w", str(rootfs), str(PX4_BUILD / "etc")]
    else:
        parm = ARDUCOPTER.parents[3] / "Tools" / "autotest" / "default_params" / "copter.parm"
        defaults = str(parm)
        if params:
            extra = workdir / "extra.parm"
            extra.write_text("".join(f"{k} {v}\n" for k, v in params.items()))
            defaults += "," + str(extra)
        cmd = [str(ARDUCOPTER), "--model", model or "+", "--speedup", "1", "--defaults", defaults, "-I0", "--home", HOME, "-w"]
    # a shell stays its parent: ArduCopter SITL exits when its parent process does
    return subprocess.Popen(["bash", "-c", shlex.join(cmd) + "; true"], cwd=workdir, stdout=log, stderr=subprocess.STDOUT,
                            start_new_session=True, env=env)  # fmt: skip


def stop_sitl(proc: subprocess.Popen[bytes]) -> None:
    try:
        os.killpg(proc.pid, signal.SIGTERM)
        proc.wait(timeout=15)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    except ProcessLookupError:
        pass


def connect_string(autopilot: str) -> str:
    return "udpin:127.0.0.1:14540" if autopilot == "px4" else "tcp:127.0.0.1:5760"


def fly_command(spec: dict[str, Any], log_dir: Path, config: Path) -> tuple[list[str], dict[str, str]]:
    cmd = [spec.get("app_python") or sys.executable, "-m", "pf_offboard", "fly", "--connect", connect_string(spec["autopilot"]),
           "--config", str(config), "--log-dir", str(log_dir), "--quiet", "--output", spec["output"], *spec.get("launch", ["--takeoff", "2"])]  # fmt: skip
    if spec.get("laps"):
        cmd += ["--laps", str(spec["laps"])]
    if spec.get("duration"):
        cmd += ["--duration", str(spec["duration"])]
    if spec["autopilot"] == "arducopter":
        cmd.append("--set-guid-options")
    env = dict(os.environ)
    if spec.get("app_path"):
        env["PYTHONPATH"] = str(spec["app_path"])
    return cmd, env


# ------------------------------------------------------------------------------------ measuring
def measure(log_dir: Path, config: Path, ulog: Path | None, settle_s: float = 8.0) -> dict[str, Any]:
    """Figures of one flight (JSON-ready)."""
    from pf_offboard.config import load_config
    from pf_offboard.logs import measures
    from pf_offboard.logs.steplog import read_steplog

    path = load_config(config).path.spline()
    recs = read_steplog(log_dir / "flight.csv")
    out: dict[str, Any] = {"tracking": None, "truth": None}
    if not path.closed:
        # an open path: the figures up to the first step at its end; what the vehicle did after
        # it (it flies on at the path speed until it stops, or stops on a slowing reference) is
        # reported apart
        import numpy as np

        # (or where the reference starts its final slow-down for the stop at the end, after the start)
        active = [r for r in recs if r.active]
        t_mid = active[0].time_s + settle_s if active else math.inf
        slowing = measures.final_slowdown([r.speed_ref_m_s for r in recs], [r.active and r.time_s > t_mid for r in recs])
        at_end = [i for i, r in enumerate(recs) if r.active and (r.lam >= path.lam_max - 1e-6 or slowing[i])]
        if at_end:
            after = recs[at_end[0]:]
            out["past_the_end"] = {"cross_track_max_m": max(r.cross_track_m for r in after),
                                   "duration_s": after[-1].time_s - after[0].time_s,
                                   # past the end point, along the path's direction there
                                   "overshoot_m": max(0.0, float(max(np.dot(np.subtract(r.position_enu_m, path.eval_floats(path.lam_max)[0:3]),
                                                                            measures.path_tangent(path)(path.lam_max)) for r in after)))}  # fmt: skip
            recs = recs[: at_end[0]]
    track = measures.tracking_of_records(recs, measures.path_tangent(path), settle_s)
    if track is None:
        return out
    out["tracking"] = {
        "convergence_time_s": track.convergence_time_s,
        "settled": None if track.settled is None else track.settled.to_dict(),
        "whole": None if track.whole is None else track.whole.to_dict(),
    }
    if ulog is not None:
        from pf_offboard.logs import truth

        try:
            t, ned = truth.read_ulog_truth(ulog)
            out["truth"] = truth.judge_truth(recs, t, ned, path, settle_s).to_dict()
        except Exception as exc:  # noqa: BLE001 - a report, not a gate
            out["truth"] = {"error": f"{type(exc).__name__}: {exc}"}
    return out


def speed_profile_config(config: Path, max_speed_m_s: float, out: Path) -> Path:
    import yaml

    data = yaml.safe_load(config.read_text())
    data["speed_profile"] = {"max_speed_m_s": max_speed_m_s}
    target = out / f"{config.stem}-fast.yaml"
    target.write_text(yaml.safe_dump(data, sort_keys=False))
    return target


def run_one(spec: dict[str, Any]) -> dict[str, Any]:
    """One flight, in the current network namespace (the caller made it private)."""
    work = Path(spec["workdir"])
    work.mkdir(parents=True, exist_ok=True)
    for old in ("log", "sitl"):  # a fresh flight
        subprocess.run(["rm", "-rf", str(work / old)], check=False)
    config = Path(spec["config"])
    if spec.get("max_speed_m_s"):
        config = speed_profile_config(config, float(spec["max_speed_m_s"]), work)
    if spec.get("config_extra"):
        import yaml

        data = yaml.safe_load(config.read_text())
        data.update(spec["config_extra"])
        config = work / f"{config.stem}-flown.yaml"
        config.write_text(yaml.safe_dump(data, sort_keys=False))
    log_dir = work / "log"
    sitl = start_sitl(spec["autopilot"], work / "sitl", spec.get("params"), spec.get("px4_env"), spec.get("model"))
    result: dict[str, Any] = {"spec": spec, "load_1min": [os.getloadavg()[0]]}  # a loaded machine perturbs real-time SITLs
    t0 = time.monotonic()
    launch_log = (work / "launch.log").open("w")
    try:
        cmd, env = fly_command(spec, log_dir, config)
        time.sleep(spec.get("start_delay_s") or 0.0)  # another stretch of SIH's fixed noise sequence (--delay-step)
        if spec.get("fast_start"):
            # the app needs ~2-3 s to start, connect and stream its proof of life before it
            # switches to OFFBOARD: the vehicle is sent away first and leaves at speed meanwhile
            # (the state at activation is in the step log)
            gcs = px4_takeoff(spec, launch_log)
            px4_send_away(gcs, spec, launch_log)
            gcs.close()
            time.sleep(spec["fast_start"]["delay_s"])
        fly = subprocess.Popen(cmd, env=env, cwd=work, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        if spec.get("throw"):
            time.sleep(1.0)  # the app holds SERIAL0 (ArduCopter's clock starts with its first client)
            arducopter_throw(spec, launch_log)
        out, err = fly.communicate(timeout=spec.get("timeout_s", 300))
        result.update(exit_code=fly.returncode, stdout=out[-4000:], stderr=err[-4000:])
    except subprocess.TimeoutExpired as exc:
        fly.kill()
        result.update(exit_code=None, stderr=f"timeout: {exc}")
    except Exception as exc:  # noqa: BLE001 - a launch that failed is a result too
        result.update(exit_code=None, stderr=f"launch: {type(exc).__name__}: {exc}")
        try:
            fly.kill()
        except Exception:  # noqa: BLE001
            pass
    finally:
        stop_sitl(sitl)
        launch_log.close()
    result["wall_s"] = time.monotonic() - t0
    result["load_1min"].append(os.getloadavg()[0])
    if (log_dir / "flight.csv").exists():
        from pf_offboard.logs.truth import find_ulog

        ulog = find_ulog(work / "sitl") if spec["autopilot"] == "px4" else None
        result["ulog"] = None if ulog is None else str(ulog)
        try:
            result.update(measure(log_dir, config, ulog))
        except Exception as exc:  # noqa: BLE001
            result["measure_error"] = f"{type(exc).__name__}: {exc}"
    (work / "result.json").write_text(json.dumps(result, indent=2, default=float))
    return result


# ------------------------------------------------------------------------------------ launches
def _gcs(url: str, timeout_s: float = 60.0) -> Any:
    """A ground-station link (system 255) that has heard the autopilot."""
    from pymavlink import mavutil

    deadline = time.monotonic() + timeout_s
    while True:
        try:
            m = mavutil.mavlink_connection(url, source_system=255, source_component=190, autoreconnect=True)
            break
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.5)
    if m.wait_heartbeat(timeout=timeout_s) is None:
        raise RuntimeError(f"no HEARTBEAT on {url}")
    return m


def _command(m: Any, cmd: int, *params: float, want: int = 0, timeout_s: float = 3.0) -> int:
    p = [*params, *([0.0] * (7 - len(params)))]
    m.mav.command_long_send(m.target_system, m.target_component, cmd, 0, *p)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        ack = m.recv_match(type="COMMAND_ACK", blocking=True, timeout=0.5)
        if ack is not None and ack.command == cmd:
            return int(ack.result)
    return -1


def _set_param(m: Any, name: str, value: float) -> None:
    from pymavlink import mavutil

    m.mav.param_set_send(m.target_system, m.target_component, name.encode(), float(value), mavutil.mavlink.MAV_PARAM_TYPE_REAL32)
    time.sleep(0.2)


def _until(pred: Any, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if pred():
            return
        time.sleep(0.1)
    raise RuntimeError(f"timed out: {what}")


def arducopter_throw(spec: dict[str, Any], log: Any) -> None:
    """On the GCS port: THROW mode, arm (retried until the EKF is ready), then the shove."""
    from pymavlink import mavutil

    th = spec["throw"]
    m = _gcs("tcp:127.0.0.1:5762")
    m.mav.request_data_stream_send(m.target_system, m.target_component, mavutil.mavlink.MAV_DATA_STREAM_ALL, 10, 1)
    for k, v in th.get("params", {}).items():
        _set_param(m, k, v)
    deadline = time.monotonic() + 150
    while True:
        m.mav.set_mode_send(m.target_system, mavutil.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 18)  # THROW
        time.sleep(0.3)
        if _command(m, mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == 0:
            break
        if time.monotonic() > deadline:
            raise RuntimeError("ArduCopter did not arm in THROW mode")
        time.sleep(2.0)
    print(f"armed in THROW at {time.strftime('%H:%M:%S')}", file=log, flush=True)
    time.sleep(2.0)
    for axis in ("X", "Y", "Z"):
        _set_param(m, f"SIM_SHOVE_{axis}", th.get(axis.lower(), 0.0))
    _set_param(m, "SIM_SHOVE_TIME", th["ms"])
    print(f"shoved {th}", file=log, flush=True)
    t_end = time.monotonic() + 5.0
    while time.monotonic() < t_end:  # the autopilot's own account of the throw
        msg = m.recv_match(type="STATUSTEXT", blocking=True, timeout=0.5)
        if msg is not None:
            print(f"{time.monotonic():.2f} autopilot: {msg.text}", file=log, flush=True)
    m.close()


def px4_takeoff(spec: dict[str, Any], log: Any) -> Any:
    """On PX4's GCS link: arm, take off (MIS_TAKEOFF_ALT) and settle in AUTO.LOITER. Returns the link."""
    from pymavlink import mavutil

    m = _gcs("udpin:127.0.0.1:14550")

    def ok_arm() -> bool:
        return _command(m, mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == 0

    _until(ok_arm, 90, "PX4 arming")
    _command(m, mavutil.mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, math.nan)

    def alt() -> float:
        lp = m.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=0.5)
        return -lp.z if lp is not None else 0.0

    _until(lambda: alt() > 2.0, 60, "take-off")
    time.sleep(3.0)
    print(f"{time.monotonic():.2f} hovering", file=log, flush=True)
    return m


def px4_send_away(m: Any, spec: dict[str, Any], log: Any) -> None:
    """A reposition far away at ``speed_m_s``: the vehicle leaves the path at cruise speed."""
    from pymavlink import mavutil

    fs = spec["fast_start"]
    home = m.recv_match(type="GLOBAL_POSITION_INT", blocking=True, timeout=3.0)
    lat, lon = home.lat * 1e-7, home.lon * 1e-7
    tlat = lat + fs["north_m"] / 6371000.0 * 180 / math.pi
    tlon = lon + fs["east_m"] / (6371000.0 * math.cos(math.radians(lat))) * 180 / math.pi
    # PX4 takes DO_REPOSITION only in MAV_FRAME_GLOBAL_INT (altitude AMSL): hold the current altitude
    m.mav.command_int_send(m.target_system, m.target_component, mavutil.mavlink.MAV_FRAME_GLOBAL_INT,
                           mavutil.mavlink.MAV_CMD_DO_REPOSITION, 0, 0, fs.get("speed_m_s", -1), 1, 0, math.nan,
                           int(tlat * 1e7), int(tlon * 1e7), home.alt * 1e-3)  # fmt: skip
    print(f"{time.monotonic():.2f} sent away: {fs}", file=log, flush=True)


# Thrown starts on ArduCopter SITL (SIM_SHOVE_*: m/s^2 in the body frame, ~ north/east/down on the
# ground at the default home heading, for SIM_SHOVE_TIME ms) and fast off-path starts on PX4 SIH
# (a reposition at cruise speed away from the path, engaged on the way).
MOTORS_IDLE = {"THROW_MOT_START": 1}  # the motors idle while armed in THROW mode (spool-up is then shorter)
THROWS: tuple[dict[str, Any], ...] = (
    {"z": -30.0, "ms": 300, "params": MOTORS_IDLE},  # straight up, 6 m/s
    {"x": 12.0, "z": -30.0, "ms": 300, "params": MOTORS_IDLE},  # and north, 3.6 m/s sideways
    {"y": 12.0, "z": -30.0, "ms": 300, "params": MOTORS_IDLE},  # east
    {"x": -9.0, "y": -9.0, "z": -30.0, "ms": 300, "params": MOTORS_IDLE},  # south-west, 3.8 m/s sideways
    {"x": -13.0, "y": 4.0, "z": -28.0, "ms": 300, "params": MOTORS_IDLE},  # south, 4.1 m/s sideways
)
# sent away at ``speed_m_s``; ``fly --airborne`` is started ``delay_s`` later and takes over ~2-3 s
# after that (on a loaded 2-core machine)
FAST_STARTS: tuple[dict[str, float], ...] = (
    {"north_m": 30.0, "east_m": 0.0, "speed_m_s": 2.0, "delay_s": 0.0},
    {"north_m": -20.0, "east_m": 20.0, "speed_m_s": 2.5, "delay_s": 0.0},
    {"north_m": 0.0, "east_m": -30.0, "speed_m_s": 3.0, "delay_s": 0.0},
    {"north_m": -30.0, "east_m": 0.0, "speed_m_s": 3.0, "delay_s": 0.0},
    {"north_m": 20.0, "east_m": 20.0, "speed_m_s": 2.5, "delay_s": 0.0},
)
# a fast start ends metres outside the default fence (the path's box grown by 2 m) and farther
# from the path than the default limits (3 m): the user who flies one sets them
FAST_START_SAFETY = {"safety": {"fence_margin_m": 15.0, "max_path_distance_at_activation_m": 15.0, "max_path_distance_m": 15.0}}


def throw_spec(throw: dict[str, Any], workdir: Path, config: Path, height_m: float = 1.8, output: str = "attitude") -> dict[str, Any]:
    return {"autopilot": "arducopter", "config": str(config), "output": output, "launch": ["--throw", str(height_m)],
            "duration": 10, "workdir": str(workdir), "throw": {**throw}}  # fmt: skip


def fast_start_spec(fast: dict[str, float], workdir: Path, config: Path, output: str = "acceleration") -> dict[str, Any]:
    return {"autopilot": "px4", "config": str(config), "output": output, "launch": ["--airborne"], "duration": 10,
            "workdir": str(workdir), "fast_start": {**fast}, "config_extra": FAST_START_SAFETY}  # fmt: skip


def start_figures(result: dict[str, Any]) -> str:
    """Activation, convergence (<= 10 cm for 1 s) and the flight after it, from the step log."""
    from pf_offboard.config import load_config
    from pf_offboard.logs import measures
    from pf_offboard.logs.steplog import read_steplog

    work = Path(result["spec"]["workdir"])
    if not (work / "log" / "flight.csv").exists():
        return "no step log"
    recs = read_steplog(work / "log" / "flight.csv")
    act = [r for r in recs if r.active]
    if not act:
        return "never activated"
    a = act[0]
    speed = float(sum(v * v for v in a.velocity_enu_m_s) ** 0.5)
    path = load_config(Path(result["spec"]["config"])).path.spline()
    track = measures.tracking_of_records(recs, measures.path_tangent(path), settle_s=3.0)
    conv = None if track is None else track.convergence_time_s
    after = [r.cross_track_m for r in act if conv is not None and r.time_s >= a.time_s + conv]
    return (f"activated at {a.position_enu_m[2]:.2f} m up, {a.cross_track_m:.2f} m off the path, moving {speed:.2f} m/s; "
            f"converged (<= 10 cm for 1 s) {'never' if conv is None else f'{conv:.2f} s'} after activation; then cross-track max "
            f"{100 * max(after) if after else float('nan'):.1f} cm; "
            f"{'from activation + 3 s: n/a' if track is None or track.settled is None else track.settled.line()}")  # fmt: skip


# ------------------------------------------------------------------------------------ the campaign
def in_namespace(spec_file: Path) -> list[str]:
    """The command flying ``spec_file`` in its own network namespace and, when the flight's files
    are outside /tmp, its own /tmp (PX4 takes /tmp/px4_lock-0: two PX4 SITLs share it otherwise)."""
    private_tmp = "" if spec_file.resolve().is_relative_to("/tmp") else "mount -t tmpfs tmpfs /tmp && "
    inner = (f"{private_tmp}ip link set lo up && exec {shlex.quote(sys.executable)} "
             f"{shlex.quote(str(Path(__file__).resolve()))} --one {shlex.quote(str(spec_file))}")
    return ["unshare", "-n", "-m", "bash", "-c", inner] if private_tmp else ["unshare", "-n", "bash", "-c", inner]


def _lap_times(spec: dict[str, Any]) -> str:
    """The flight's lap times beside the point-mass bound at the vehicle's limits, from the
    summary.json fly wrote ("" without them: an open path, or an app that did not write them)."""
    try:
        summary = json.loads((Path(spec["workdir"]) / "log" / "summary.json").read_text()).get("summary") or {}
    except (OSError, ValueError, KeyError):
        return ""
    laps, bound = summary.get("lap_times_s") or [], summary.get("lap_time_bound_s")
    if not laps or bound is None:
        return ""
    return f"lap times {', '.join(f'{x:.2f}' for x in laps)} s (the first from activation); point-mass bound {bound:.2f} s"


def _identified(spec: dict[str, Any]) -> str:
    """The inner-loop model the app adopted in flight, from the summary.json fly wrote ("" when the
    app wrote none: an older checkout)."""
    try:
        summary = json.loads((Path(spec["workdir"]) / "log" / "summary.json").read_text()).get("summary") or {}
    except (OSError, ValueError, KeyError):
        return ""
    if "identified_model" not in summary:
        return ""
    m = summary["identified_model"]
    if m is None:
        return "identified: none adopted"
    after = m["adopted_at_s"] - (summary.get("activation_time_s") or math.nan)
    return (f"identified: lag {m['lag_s']:.3f} s, dead time {m['delay_s']:.3f} s, drag {m['drag_1_s']:.3f} 1/s, "
            f"adopted {after:.1f} s after activation")  # fmt: skip


def row(result: dict[str, Any]) -> str:
    spec = result["spec"]
    tr = result.get("tracking") or {}
    s = tr.get("settled") or {}
    cm = lambda x: "  n/a" if x is None else f"{100 * x:5.1f}"  # noqa: E731
    line = (f"{spec['autopilot']:10s} {Path(spec['config']).stem:15s} {spec['output']:12s} "
            f"{'v<=' + str(spec['max_speed_m_s']) if spec.get('max_speed_m_s') else 'v=1.5':7s} exit {result.get('exit_code')!s:4s} "
            f"ct RMS {cm(s.get('cross_track_rms_m'))} max {cm(s.get('cross_track_max_m'))} cm | speed err RMS {cm(s.get('speed_error_rms_m_s'))} "
            f"mean {cm(s.get('speed_error_mean_m_s'))} cm/s (est {cm(s.get('estimator_speed_error_rms_m_s'))}) | mean speed "
            f"{s.get('speed_mean_m_s') or math.nan:.2f} m/s | conv {tr.get('convergence_time_s')}")  # fmt: skip
    if result.get("load_1min"):
        line += f" | load {'-'.join(f'{x:.1f}' for x in result['load_1min'])}"
    if result.get("past_the_end"):
        pe = result["past_the_end"]
        line += f"\n{'':38s}(window ends at the open path's end; after it: overshoot {cm(pe['overshoot_m'])} cm, cross-track max {cm(pe['cross_track_max_m'])} cm over {pe['duration_s']:.1f} s)"
    for extra in (_lap_times(spec), _identified(spec)):
        if extra:
            line += f"\n{'':38s}{extra}"
    t = result.get("truth")
    if t and "error" not in t:
        w = t.get("truth") or {}
        line += (f"\n{'':38s}truth: ct RMS {cm(w.get('cross_track_rms_m'))} max {cm(w.get('cross_track_max_m'))} cm, speed err RMS "
                 f"{cm(w.get('speed_error_rms_m_s'))} cm/s; EKF2 err RMS N,E,D {', '.join(cm(x) for x in t['estimate_error_rms_ned_m'])} cm "
                 f"(horiz {cm(t['estimate_error_rms_horizontal_m'])}); offset N,E,D {', '.join(cm(x) for x in t['frame_offset_ned_m'])} cm; "
                 f"raw truth ct RMS {cm(t['truth_raw_cross_track_rms_m'])}")  # fmt: skip
    elif t:
        line += f"\n{'':38s}truth: {t['error']}"
    if result.get("exit_code") != 0:
        err = (result.get("stderr") or "").strip().splitlines()
        why = [x for x in err if x.startswith("pf-offboard fly:")] or err[-1:]
        line += f"\n{'':38s}{why[-1] if why else ''}"
    return line


def table(directory: Path) -> list[str]:
    """One Markdown row per (autopilot, path, output, speed): ranges over the repeats, from activation + 8 s."""
    groups: dict[tuple[str, str, str, float], list[dict[str, Any]]] = {}
    for res_file in sorted(directory.glob("*/result.json")):
        d = json.loads(res_file.read_text())
        s = d["spec"]
        if s.get("throw") or s.get("fast_start"):
            continue
        groups.setdefault((s["autopilot"], Path(s["config"]).stem, s["output"], s.get("max_speed_m_s") or 1.5), []).append(d)

    def rng(values: list[Any], k: float = 100.0, fmt: str = ".1f") -> str:
        v = [x * k for x in values if x is not None]
        if not v:
            return "n/a"
        lo, hi = f"{min(v):{fmt}}", f"{max(v):{fmt}}"
        return lo if lo == hi else f"{lo}-{hi}"

    out = ["| autopilot | path | output | speed | flights | exit | cross-track RMS cm | max cm | speed error RMS cm/s (position) | "
           "(estimator) | mean speed m/s | truth cross-track RMS cm | EKF2 error horiz / vert cm |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for key in sorted(groups):
        ds = groups[key]
        w = [((d.get("tracking") or {}).get("settled") or {}) for d in ds]
        t = [d["truth"] for d in ds if d.get("truth") and "error" not in d["truth"]]
        truth = f"{rng([(x.get('truth') or {}).get('cross_track_rms_m') for x in t])}" if t else "-"
        ekf = (f"{rng([x['estimate_error_rms_horizontal_m'] for x in t])} / {rng([x['estimate_error_rms_ned_m'][2] for x in t])}") if t else "-"
        out.append(f"| {key[0]} | {key[1]} | {key[2]} | {'profile ' + format(key[3], 'g') if key[3] != 1.5 else '1.5'} | {len(ds)} | "
                   f"{','.join(str(d.get('exit_code')) for d in ds)} | {rng([x.get('cross_track_rms_m') for x in w])} | "
                   f"{rng([x.get('cross_track_max_m') for x in w])} | {rng([x.get('speed_error_rms_m_s') for x in w])} | "
                   f"{rng([x.get('estimator_speed_error_rms_m_s') for x in w])} | {rng([x.get('speed_mean_m_s') for x in w], 1.0, '.2f')} | "
                   f"{truth} | {ekf} |")  # fmt: skip
    return out


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--one", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--out", type=Path, default=Path("runs") / time.strftime("campaign-%Y%m%dT%H%M%S"))
    ap.add_argument("--autopilots", default="px4,arducopter")
    ap.add_argument("--paths", default="figure8-tilted,helix,racetrack", help=f"config names in {CONFIG_DIR} or YAML files")
    ap.add_argument("--outputs", help="default: every mode the autopilot allows")
    ap.add_argument("--speeds", default="1.5,3.0", help="1.5: the config's speed; anything else: speed_profile.max_speed_m_s")
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--app-python", help="python that runs the app (default: this one)")
    ap.add_argument("--app-path", help="PYTHONPATH for the app (another checkout)")
    ap.add_argument("--px4-param", action="append", default=[], metavar="NAME=VALUE", help="a PX4 parameter for every PX4 flight")
    ap.add_argument("--arducopter-param", action="append", default=[], metavar="NAME=VALUE",
                    help="an ArduCopter parameter for every ArduCopter flight (e.g. FRAME_CLASS=2 with --arducopter-model hexa)")
    ap.add_argument("--arducopter-model", help="ArduCopter SITL's frame model (default +)")
    ap.add_argument("--px4-env", action="append", default=[], metavar="NAME=VALUE",
                    help="an environment variable for every PX4 SITL (e.g. PX4_SIH_NOISE_SCALE=0 on a SIH built to read it)")
    ap.add_argument("--delay-step", type=float, default=0.0, metavar="S",
                    help="repeat k starts the app k*S s after its SITL: PX4 SIH seeds its sensor noise with a "
                         "constant (srand(1234)), so flights started alike fly nearly the same noise; delays give "
                         "each repeat its own stretch of it (about the same for every config and output)")
    ap.add_argument("--tag", default="", help="appended to each flight's directory name")
    ap.add_argument("--starts", action="store_true", help="the thrown starts (ArduCopter) and fast off-path starts (PX4) instead")
    ap.add_argument("--table", type=Path, metavar="DIR", help="a Markdown table of a campaign's flights (ranges over repeats)")
    ap.add_argument("--report", type=Path, metavar="DIR", help="measure the flights under DIR again and print them (no flying)")
    return ap


def flight_specs(args: argparse.Namespace) -> list[dict[str, Any]]:
    """The campaign's flights, in flying order (repeat, speed, path, autopilot, output)."""
    specs = []
    for rep in range(args.repeat):
        for speed in (float(s) for s in args.speeds.split(",")):
            for name in args.paths.split(","):
                config = Path(name) if name.endswith(".yaml") else CONFIG_DIR / f"{name}.yaml"
                closed = "closed: false" not in config.read_text()
                for autopilot in args.autopilots.split(","):
                    for output in (args.outputs.split(",") if args.outputs else OUTPUTS[autopilot]):
                        if output not in OUTPUTS[autopilot]:
                            continue
                        tag = f"{autopilot}-{config.stem}-{output}-v{speed:g}-{rep}{args.tag}"
                        specs.append({"autopilot": autopilot, "config": str(config.resolve()), "output": output,
                                      "max_speed_m_s": None if speed == 1.5 else speed, "laps": 3 if closed else 1,
                                      "workdir": str((args.out / tag).resolve()), "app_python": args.app_python,
                                      "app_path": args.app_path, "start_delay_s": rep * args.delay_step,
                                      "params": dict(kv.split("=", 1) for kv in (args.px4_param if autopilot == "px4" else args.arducopter_param)) or None,
                                      "model": args.arducopter_model if autopilot == "arducopter" else None,
                                      "px4_env": dict(kv.split("=", 1) for kv in args.px4_env) if autopilot == "px4" else None})  # fmt: skip
    return specs


def main(argv: list[str] | None = None) -> int:
    ap = build_parser()
    args = ap.parse_args(argv)
    if not (math.isfinite(args.delay_step) and args.delay_step >= 0.0):
        ap.error(f"--delay-step: must be a finite number of seconds >= 0, got {args.delay_step:g}")
    if args.table:
        print("\n".join(table(args.table)))
        return 0
    if args.report:
        from pf_offboard.logs.truth import find_ulog

        for res_file in sorted(args.report.glob("*/result.json")):
            res = json.loads(res_file.read_text())
            work = res_file.parent
            if (work / "log" / "flight.csv").exists():
                config = Path(res["spec"]["config"])
                fast = work / f"{config.stem}-fast.yaml"
                ulog = find_ulog(work / "sitl") if res["spec"]["autopilot"] == "px4" else None
                res.update(measure(work / "log", fast if fast.exists() else config, ulog))
                res_file.write_text(json.dumps(res, indent=2, default=float))
            print(row(res))
        return 0
    if args.one:
        run_one(json.loads(args.one.read_text()))
        return 0
    if args.starts:
        args.out.mkdir(parents=True, exist_ok=True)
        jobs: dict[str, list[dict[str, Any]]] = {"arducopter": [], "px4": []}
        for i, th in enumerate(THROWS):
            jobs["arducopter"].append(throw_spec(th, (args.out / f"throw-{i}").resolve(), CONFIG_DIR / "racetrack.yaml"))
        for i, fs in enumerate(FAST_STARTS):
            jobs["px4"].append(fast_start_spec(fs, (args.out / f"fast-start-{i}").resolve(), CONFIG_DIR / "racetrack.yaml"))

        def start_worker(specs: list[dict[str, Any]]) -> None:
            for spec in specs:
                spec.update(app_python=args.app_python, app_path=args.app_path)
                work = Path(spec["workdir"])
                work.mkdir(parents=True, exist_ok=True)
                (work / "spec.json").write_text(json.dumps(spec))
                subprocess.run(in_namespace(work / "spec.json"), check=False)
                res = json.loads((work / "result.json").read_text()) if (work / "result.json").exists() else {"spec": spec}
                print(f"{work.name}: exit {res.get('exit_code')}; {start_figures(res)}", flush=True)
                if res.get("exit_code") != 0:
                    print(f"    {(res.get('stderr') or '').strip().splitlines()[-3:]}", flush=True)

        threads = [threading.Thread(target=start_worker, args=(v,)) for k, v in jobs.items() if k in args.autopilots.split(",")]
        for th in threads:
            th.start()
        for th in threads:
            th.join()
        return 0
    args.out.mkdir(parents=True, exist_ok=True)
    queues: dict[str, queue.Queue[dict[str, Any]]] = {}
    specs = flight_specs(args)
    for spec in specs:
        queues.setdefault(spec["autopilot"], queue.Queue()).put(spec)
    lock = threading.Lock()
    results: list[dict[str, Any]] = []

    def worker(q: queue.Queue[dict[str, Any]]) -> None:
        while True:
            try:
                spec = q.get_nowait()
            except queue.Empty:
                return
            work = Path(spec["workdir"])
            work.mkdir(parents=True, exist_ok=True)
            res_file = work / "result.json"
            done = json.loads(res_file.read_text()) if res_file.exists() else None
            if not (done and done.get("exit_code") == 0):
                res_file.unlink(missing_ok=True)
                (work / "spec.json").write_text(json.dumps(spec))
                subprocess.run(in_namespace(work / "spec.json"), check=False)
            res = json.loads(res_file.read_text()) if res_file.exists() else {"spec": spec, "exit_code": "crashed"}
            with lock:
                results.append(res)
                print(row(res), flush=True)

    threads = [threading.Thread(target=worker, args=(q,)) for q in queues.values()]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    (args.out / "results.json").write_text(json.dumps(results, indent=2, default=float))
    print(f"\n{len(results)} flights; results in {args.out / 'results.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
