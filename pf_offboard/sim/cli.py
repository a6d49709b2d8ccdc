"""``pf-offboard sim``: fly a config in process against the mock autopilot and write the logs."""

from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from sitl_mock.dynamics.params import DEFAULT_VEHICLE, PRESET_NAMES

    parser.add_argument("--config", required=True, metavar="YAML", help="config file, or a shipped config's name (pf-offboard configs)")
    start = parser.add_mutually_exclusive_group()
    start.add_argument("--start", metavar="X,Y,Z", help="hover start, world ENU metres (z up); default: the path's start")
    start.add_argument("--throw", metavar="X,Y,Z,VX,VY,VZ",
                       help="thrown start, world ENU (z up), m and m/s; motors locked until the throw trigger")  # fmt: skip
    parser.add_argument("--throw-height", type=float, metavar="H", help="throw activation height, m (default: config, else 2)")
    parser.add_argument("--throw-attitude", metavar="QW,QX,QY,QZ",
                        help="attitude at the throw: body FLU -> world ENU unit quaternion (default level, nose north)")
    parser.add_argument("--throw-rates", metavar="P,Q,R", help="body rates at the throw, body FLU rad/s (default 0)")
    parser.add_argument("--throw-engage-after", type=float, metavar="S",
                        help="engage S simulated seconds after the throw (0: at once) instead of at the activation height")
    parser.add_argument("--autopilot", choices=("px4", "ardupilot"), default="px4", help="mock autopilot profile (default px4)")
    parser.add_argument("--vehicle", choices=PRESET_NAMES, default=DEFAULT_VEHICLE,
                        help=f"simulated airframe (default {DEFAULT_VEHICLE}): fast = paper-like ideal, px4-sih = PX4's SIH "
                        "quad (calibrated lag, drag, EKF-like position/velocity error), arducopter, px4-default")
    parser.add_argument("--wind", metavar="E,N[,U]",
                        help="constant wind, world ENU m/s (air velocity: 3,0 blows toward east at 3 m/s; U default 0)")
    parser.add_argument("--wind-gusts", metavar="STD[,TAU]",
                        help="random gusts on top of --wind: std m/s per axis, time constant s (default 2); seeded by --seed")
    parser.add_argument("--push", metavar="T,DURATION,AX,AY[,AZ]",
                        help="an external push: from simulated time T s for DURATION s, specific force AX,AY,AZ m/s^2 "
                        "world ENU (AZ default 0), e.g. 8,0.5,-10,0")
    parser.add_argument("--output", choices=("acceleration", "attitude", "rates"), help="setpoint type (default: config)")
    parser.add_argument("--rate", type=float, metavar="HZ", help="control/telemetry rate (default: config flight.setpoint_rate_hz)")
    end = parser.add_mutually_exclusive_group()
    end.add_argument("--duration", type=float, metavar="S", help="simulated seconds (default 20)")
    end.add_argument("--laps", type=float, metavar="N", help="end after N laps along the path")
    parser.add_argument("--seed", type=int, default=0, help="seed of the simulation's random generator")
    parser.add_argument("--epoch", type=float, metavar="UNIX_S", help="UNIX time of t=0 in the .tlog (default: now)")
    parser.add_argument("--name", default="flight", help="log file stem (default flight)")
    parser.add_argument("--json", action="store_true", help="print the flight report (as in OUT/summary.json) as JSON instead of text")
    parser.add_argument("--out", required=True, metavar="DIR", help="directory for NAME.tlog, NAME.csv, NAME.yaml")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from pf_offboard.errors import InputError
    from pf_offboard.logs._io import make_dir
    from pf_offboard.sim.flight import (SimSpec, parse_gusts, parse_push, parse_quaternion, parse_rates, parse_start,
                                        parse_throw, parse_wind, simulate)

    from pf_offboard.shipped import resolve_config

    args.config = str(resolve_config(args.config))  # a file, or a shipped config's name
    spec = SimSpec(
        start_enu_m=parse_start(args.start) if args.start else None,
        throw_enu=parse_throw(args.throw) if args.throw else None,
        throw_height_m=args.throw_height,
        throw_q_enu_flu=parse_quaternion(args.throw_attitude) if args.throw_attitude is not None else None,
        throw_body_rates_flu_rad_s=parse_rates(args.throw_rates) if args.throw_rates is not None else None,
        throw_engage_after_s=args.throw_engage_after,
        autopilot=args.autopilot,
        vehicle=args.vehicle,
        wind_enu_m_s=parse_wind(args.wind) if args.wind is not None else None,
        wind_gusts=parse_gusts(args.wind_gusts) if args.wind_gusts is not None else None,
        push=parse_push(args.push) if args.push is not None else None,
        output_mode=args.output,
        rate_hz=args.rate,
        duration_s=args.duration,
        laps=args.laps,
        seed=args.seed,
        epoch_unix_s=args.epoch,
        name=args.name,
    )
    make_dir(args.out, "--out")
    result = simulate(args.config, spec, args.out)
    if not args.json:
        print(f"pf-offboard sim: {result.reason} after {result.sim_time_s:.2f} s simulated"
              + (" (CRASHED)" if result.crashed else ""))  # fmt: skip
    code = 1 if result.crashed else 0
    if args.json:  # the report simulate() wrote beside the logs
        from pf_offboard.logs.summary import SUMMARY_JSON

        print((result.paths.tlog.parent / SUMMARY_JSON).read_text(encoding="utf-8"), end="")
        return code
    for line in result.summary.lines():
        print("  " + line)
    print(f"logs: {result.paths.tlog} {result.paths.steps_csv}")
    return code
