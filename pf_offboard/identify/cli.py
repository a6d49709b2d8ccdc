"""``pf-offboard identify``: fit the vehicle's inner-loop response (VehicleModel) from flight logs,
or fly a short bounded excitation first (``--connect``). See docs/identify.md.

Exit codes: 0 fitted; 2 bad input (missing / unreadable log, no setpoints, too short, no
excitation — one line naming the file and the reason); 3 link error during ``--connect``;
4 the operator took the vehicle over during the excitation.
"""

from __future__ import annotations

import argparse
import sys


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("logs", nargs="*", metavar="LOG", help="fly / sim .tlog or .tlog.gz, or a PX4 ULog .ulg of an offboard flight (several: fitted together)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON instead of the report")
    parser.add_argument("--write-config", metavar="FILE",
                        help="write FILE with the identified vehicle: section (FILE or --config as the base, other sections kept)")  # fmt: skip
    parser.add_argument("--hover-thrust", type=float, metavar="H",
                        help="normalised hover thrust the app used for attitude/rates setpoints (default: the log's config, else its parameter)")  # fmt: skip
    parser.add_argument("--velocity-correction", type=float, metavar="S",
                        help="fit the velocity made consistent with the position's derivative (time constant S s, as "
                             "flight.velocity_correction_s); for path-following logs of an estimator whose velocity drifts "
                             "from its position, e.g. PX4 SIH; not for hover excitations (default: as reported; docs/identify.md)")  # fmt: skip
    parser.add_argument("--truth", action="store_true",
                        help="a ULog from PX4's SIH simulator: fit its ground truth instead of the estimate (the airframe itself, "
                             "without EKF2's error)")  # fmt: skip
    fly = parser.add_argument_group("excitation flight (--connect)")
    fly.add_argument("--connect", metavar="ENDPOINT", help="fly a bounded excitation at hover first (about 35 s; like fly --connect), then fit its log")
    fly.add_argument("--config", metavar="YAML", help="config file or shipped name: with --connect its flight settings (output mode, rate); base of --write-config")
    fly.add_argument("--takeoff", type=float, metavar="H", help="with --connect: arm and take off to H m first (default: the vehicle is airborne)")
    fly.add_argument("--output", choices=("acceleration", "attitude", "rates"), help="setpoint type (default: flight.output_mode)")
    fly.add_argument("--duration", type=float, default=30.0, metavar="S", help="excitation length, s (default 30)")
    fly.add_argument("--box", type=float, default=1.5, metavar="M", help="abort to hold beyond M metres from the start on any axis (default 1.5)")
    fly.add_argument("--max-speed", type=float, default=2.0, metavar="M_S", help="abort above this speed (default 2 m/s)")
    fly.add_argument("--max-tilt", type=float, default=35.0, metavar="DEG", help="abort above this tilt (default 35 deg)")
    fly.add_argument("--amplitude", type=float, default=1.0, metavar="M_S2", help="horizontal doublet amplitude (default 1 m/s^2; vertical 0.8 of it)")
    fly.add_argument("--seed", type=int, default=0, help="seed of the excitation's random doublets")
    fly.add_argument("--autopilot", choices=("auto", "px4", "ardupilot"), default="auto", help="default: from HEARTBEAT")
    fly.add_argument("--target-system", type=int, metavar="ID", help="vehicle system id (default: first autopilot heard)")
    fly.add_argument("--heartbeat-timeout", type=float, default=10.0, metavar="S", help="give up without a HEARTBEAT (s)")
    fly.add_argument("--set-guid-options", action="store_true", help="ArduPilot: set the GUID_OPTIONS bits the output mode needs")
    fly.add_argument("--log-dir", metavar="DIR", help="excitation log directory (default ./flights/<UTC timestamp>/)")
    fly.add_argument("--quiet", action="store_true", help="no status line")


def run(args: argparse.Namespace) -> int:
    import math
    from pathlib import Path

    from pf_offboard.errors import InputError
    from pf_offboard.identify.fit import identify
    from pf_offboard.identify.logdata import load_log
    from pf_offboard.identify.report import as_json, report_lines, vehicle_yaml, write_config

    if args.hover_thrust is not None and not (math.isfinite(args.hover_thrust) and 0.05 <= args.hover_thrust <= 0.95):
        raise InputError("--hover-thrust", f"must be in [0.05, 0.95], got {args.hover_thrust}")
    from pf_offboard.config import VELOCITY_CORRECTION_RANGE_S

    correction = args.velocity_correction
    lo, hi = VELOCITY_CORRECTION_RANGE_S
    if correction is not None and not (math.isfinite(correction) and lo <= correction <= hi):
        raise InputError("--velocity-correction", f"must be in [{lo:g}, {hi:g}] s (flight.velocity_correction_s's range), got {correction}")
    logs = [Path(p) for p in args.logs]
    if args.config:
        from pf_offboard.shipped import resolve_config

        args.config = str(resolve_config(args.config))  # a file, or a shipped config's name
    if args.connect:
        if logs:
            raise InputError("LOG", "give either logs to fit or --connect (which records its own), not both")
        if not args.config:
            raise InputError("--config", "--connect needs --config (output mode, setpoint rate)")
        if correction is not None:
            # at hover the position's own wander is most of what the correction adds: the real PX4
            # SIH's excitations fitted a drag of -0.35 / 0.11 with it, 0.40 / 0.44 without (docs/identify.md)
            raise InputError("--velocity-correction", "is for path-following logs, not the hover excitation --connect flies")
        from pf_offboard.identify.excite import ExcitationSpec, ExciteRequest, excite

        spec = ExcitationSpec(
            duration_s=args.duration, amplitude_xy_m_s2=args.amplitude, amplitude_z_m_s2=0.8 * args.amplitude,
            box_m=args.box, max_speed_m_s=args.max_speed, max_tilt_deg=args.max_tilt, seed=args.seed,
        )  # fmt: skip
        outcome = excite(ExciteRequest.from_args(args), spec, sys.stderr)
        if outcome.exit_code != 0 or outcome.tlog is None:
            return outcome.exit_code or 3
        if outcome.aborted:
            print(f"pf-offboard identify: excitation aborted ({outcome.aborted}); fitting what was flown", file=sys.stderr)
        logs = [outcome.tlog]
    elif not logs:
        raise InputError("LOG", "give at least one .tlog or .ulg to fit, or --connect to fly an excitation")
    if args.truth and any(p.suffix.lower() != ".ulg" for p in logs):
        raise InputError("--truth", "only a PX4 ULog (.ulg) from the SIH simulator carries ground truth")
    data = [load_log(p, hover_thrust=args.hover_thrust, velocity_correction_s=correction, truth=args.truth) for p in logs]
    name = str(logs[0]) if len(logs) == 1 else f"{len(logs)} logs"
    ident = identify([s for d in data for s in d.segments], source=name)
    if args.json:
        print(as_json(ident, data))
    else:
        for line in report_lines(ident, data):
            print(line)
    if args.write_config:
        if reason := ident.unflyable():
            raise InputError("--write-config", f"{reason}; nothing written")
        base = Path(args.config) if args.config else None
        write_config(Path(args.write_config), ident, base)
        if not args.json:
            print(f"vehicle: section written to {args.write_config}")
    elif not args.json:
        print()
        if reason := ident.unflyable():
            print(f"# do not fly this section: {reason}")
        print(vehicle_yaml(ident), end="")
    return 0
