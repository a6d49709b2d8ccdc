"""``pf-offboard demo``: the paper's path flown end to end against a ``sitl-mock`` on loopback.

Starts ``python -m sitl_mock`` (PX4 profile, lockstep, ephemeral UDP port) in a subprocess, then
runs exactly what ``pf-offboard fly`` runs against it over real MAVLink: take-off to 2 m below
the paper's start point (0, −1.5, 2) m, convergence onto the path, two laps at η2_ref = −1.5 m/s,
hand-back in AUTO.LOITER. Prints the flight summary, writes the logs and the paper-style figures.

The mock vehicle is the autopilot's realistic preset (``px4-sih``: PX4's SIH quad, calibrated
against the real one, EKF-like estimate error; ``arducopter`` for the ArduPilot profile), flown
with the shipped config made for it; ``--vehicle fast`` flies the paper's ideal vehicle with the
paper's own config and gains.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from pf_offboard.errors import InputError

# The paper's first experiment starts at (0, -1.5, 2) m ENU: spawn on the ground below it.
START_ENU_M = (0.0, -1.5, 2.0)
# The mock vehicle per autopilot profile (its realistic preset), and the shipped config (the paper's
# path) made for each vehicle the demo flies.
DEMO_VEHICLES: dict[str, str] = {"px4": "px4-sih", "ardupilot": "arducopter"}
DEMO_CONFIGS: dict[str, str] = {"px4-sih": "px4-sih", "arducopter": "arducopter", "fast": "paper"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", help="config YAML file or shipped config name (default: the one made for --vehicle: "
                        "px4-sih, arducopter, or paper for fast)")
    parser.add_argument("--vehicle", choices=tuple(DEMO_CONFIGS),
                        help="mock vehicle (default: the autopilot's realistic one, px4-sih for px4, arducopter for ardupilot; "
                             "fast: the paper's ideal vehicle)")  # fmt: skip
    parser.add_argument("--laps", type=float, default=2.0, help="laps to fly (default 2)")
    parser.add_argument("--output", choices=("acceleration", "attitude", "rates"), help="setpoint type (default: from the config)")
    parser.add_argument("--autopilot", choices=("px4", "ardupilot"), default="px4", help="mock profile (default px4)")
    parser.add_argument("--log-dir", metavar="DIR", help="default: ./flights/demo-<UTC timestamp>/")
    parser.add_argument("--no-plots", action="store_true", help="skip the figures")
    parser.add_argument("--signing-key", metavar="FILE",
                        help="MAVLink 2 signing on both ends (the mock and the app) with this key file")  # fmt: skip
    parser.add_argument("--quiet", action="store_true", help="no status line")
    parser.add_argument("--json", action="store_true", help="print the flight report (LOG_DIR/summary.json) as JSON on stdout")


def demo_vehicle(args: argparse.Namespace) -> str:
    """The mock vehicle: ``--vehicle``, else the realistic preset of ``--autopilot``."""
    return args.vehicle or DEMO_VEHICLES[args.autopilot]


def paper_config(vehicle: str = "fast") -> Path:
    """The shipped config flying the paper's path on ``vehicle`` (package data: found after
    ``pip install`` from any directory): ``paper`` for the ideal vehicle, else the vehicle's own."""
    from pf_offboard.shipped import resolve_config

    return resolve_config(DEMO_CONFIGS[vehicle])


# The mock's default ("fast") vehicle: its closed body-rate loop reaches 63 % of a step within
# 12 ms. The demo knows the vehicle it flies, so rates mode gets the attitude time constant that
# fits it (4x, at least 0.05 s) instead of the 0.25 s default meant for unknown real autopilots.
DEMO_VEHICLE_RATE_TIME_CONSTANT_S = 0.012


def _with_mock_rate_loop(config: Any, config_path: Path, output: str | None) -> Path:
    """A copy of the config with ``vehicle.rate_time_constant_s`` of the demo's mock vehicle when
    it flies ``rates`` and the config says nothing about the rate loop; else ``config_path``."""
    if (output or config.flight.output_mode) != "rates":
        return config_path
    if config.flight.attitude_time_constant_s is not None or config.vehicle.rate_time_constant_s > 0.0:
        return config_path
    import tempfile

    import yaml

    data = yaml.safe_load(config_path.read_text()) or {}
    data.setdefault("vehicle", {})["rate_time_constant_s"] = DEMO_VEHICLE_RATE_TIME_CONSTANT_S
    out = Path(tempfile.mkdtemp(prefix="pf-offboard-demo-")) / config_path.name
    out.write_text(yaml.safe_dump(data, sort_keys=False))
    return out


def run(args: argparse.Namespace) -> int:
    from sitl_mock.config import MockConfig, SpawnSpec
    from sitl_mock.runner import spawn

    from pf_offboard import frames
    from pf_offboard.app.fly import add_arguments as fly_arguments
    from pf_offboard.app.fly import default_log_dir, fly
    from pf_offboard.config import load_config

    from pf_offboard.shipped import resolve_config

    vehicle = demo_vehicle(args)
    config_path = resolve_config(args.config) if args.config else paper_config(vehicle)
    if not (args.laps > 0):
        raise InputError("--laps", f"must be > 0, got {args.laps}")
    log_dir = Path(args.log_dir) if args.log_dir else default_log_dir("demo-")
    if args.log_dir:
        from pf_offboard.logs._io import make_dir

        make_dir(log_dir, "--log-dir")  # before the mock is started
    config = load_config(config_path)
    if args.signing_key:
        from pf_offboard.app.fly import signing_key_from_args

        signing_key_from_args(args)  # an unreadable key file is bad input, found before the mock starts
    if vehicle == "fast":
        config_path = _with_mock_rate_loop(config, config_path, args.output)
    rate_hz = config.flight.setpoint_rate_hz
    # PX4: lockstep (one physics step per setpoint: as fast as the host allows, deterministic).
    # ArduPilot takes off on its own (NAV_TAKEOFF) while we send nothing, which a lockstep clock
    # cannot advance: real time there, like ArduPilot SITL.
    lockstep = args.autopilot == "px4"
    start_ned = frames.enu_to_ned((START_ENU_M[0], START_ENU_M[1], 0.0))
    mock_config = MockConfig(
        profile=args.autopilot,
        vehicle=vehicle,
        spawn=SpawnSpec("ground", (float(start_ned[0]), float(start_ned[1]), 0.0)),
        udp_local_port=0,
        udp_remote=None,
        tcp_port=None,
        lockstep=lockstep,
        lockstep_dt_s=1.0 / rate_hz,
        signing_key_file=args.signing_key,
    )
    clock = f"lockstep {1000.0 / rate_hz:g} ms" if lockstep else "real time"
    print(f"pf-offboard demo: sitl-mock ({args.autopilot}, vehicle {vehicle}, {clock}) on loopback; "
          f"config {config_path}", file=sys.stderr)  # fmt: skip
    with spawn(mock_config) as mock:
        parser = argparse.ArgumentParser(prog="pf-offboard fly")
        fly_arguments(parser)
        flags = [
            "--connect", f"udpout:127.0.0.1:{mock.ports.udp}", "--config", str(config_path),
            "--takeoff", str(START_ENU_M[2]), "--laps", str(args.laps), "--log-dir", str(log_dir),
            "--autopilot", args.autopilot, "--heartbeat-timeout", "5",
        ]  # fmt: skip
        if args.output:
            flags += ["--output", args.output]
        if args.autopilot == "ardupilot":
            flags.append("--set-guid-options")
        if args.quiet:
            flags.append("--quiet")
        if args.signing_key:
            flags += ["--signing-key", args.signing_key]
        if args.json:
            flags.append("--json")
        outcome = fly(parser.parse_args(flags))
    if outcome.exit_code == 0 and outcome.log_dir is not None and not args.no_plots:
        try:
            from pf_offboard.logs.plot import make_figures
        except ImportError:  # plotting is optional for the demo
            return outcome.exit_code
        pngs = make_figures([outcome.log_dir / "flight.csv"], outcome.log_dir, config_path)
        print("figures: " + ", ".join(str(p) for p in pngs), file=sys.stderr)
    return outcome.exit_code
