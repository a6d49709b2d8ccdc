"""``sitl-mock`` command line (also ``python -m sitl_mock``).

Runs a mock PX4 (default) or ArduPilot autopilot on loopback until Ctrl-C or ``--duration``.
Bad flags: one line on stderr, exit code 2.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import signal
import sys
from collections.abc import Sequence

from sitl_mock.argv import config_to_args  # noqa: F401  (re-exported: sitl_mock.cli.config_to_args)
from sitl_mock.config import FaultConfig, MockConfig, MockConfigError, SpawnSpec
from sitl_mock.dynamics import DEFAULT_VEHICLE, PRESET_NAMES

DEFAULT_UDP_LOCAL = 14580
DEFAULT_UDP_REMOTE = "127.0.0.1:14540"
DEFAULT_TCP = 5760


def _floats(text: str, n: int | None, flag: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise MockConfigError(flag, f"numbers expected, got {text!r}") from None
    if n is not None and len(values) != n:
        raise MockConfigError(flag, f"expected {n} comma-separated numbers, got {text!r}")
    if not all(math.isfinite(v) for v in values):
        raise MockConfigError(flag, "values must be finite")
    return values


def _percent(value: float, flag: str) -> float:
    if not (0.0 <= value <= 100.0):
        raise MockConfigError(flag, f"must be a percentage in [0, 100], got {value}")
    return value / 100.0


def _host_port(text: str, flag: str) -> tuple[str, int]:
    host, _, port = text.rpartition(":")
    try:
        number = int(port)
    except ValueError:
        raise MockConfigError(flag, f"expected HOST:PORT, got {text!r}") from None
    if host not in ("127.0.0.1", "localhost"):
        raise MockConfigError(flag, "loopback only (127.0.0.1)")
    if not 1 <= number <= 65535:
        raise MockConfigError(flag, f"port out of range: {number}")
    return "127.0.0.1", number


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="sitl-mock",
        description="MAVLink mock autopilot (PX4 or ArduPilot behaviour) around a simulated quadrotor. "
        "Loopback only. Frames: NED (x north, y east, z down), metres, seconds.",
    )
    p.add_argument("--profile", choices=("px4", "ardupilot"), default="px4", help="autopilot to imitate (default px4)")
    p.add_argument("--vehicle", choices=PRESET_NAMES, default=DEFAULT_VEHICLE,
                   help=f"vehicle preset (default {DEFAULT_VEHICLE}): fast = paper-like ideal, px4-sih = PX4's SIH quad "
                   "(calibrated: lag, drag, EKF-like position/velocity error), arducopter = ArduCopter SITL's quad, "
                   "px4-default = a mid-size PX4-tuned quad")
    p.add_argument("--wind", metavar="VN,VE[,VD]",
                   help="constant wind, world NED m/s (air velocity: 3,0 blows toward north at 3 m/s; VD default 0)")
    p.add_argument("--wind-gusts", metavar="STD[,TAU]",
                   help="random gusts on top of --wind: std m/s per axis, time constant s (default 2); seeded by --seed")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="a parameter's value at start (repeatable), like PX4_PARAM_NAME=VALUE: e.g. MPC_TILTMAX_AIR=30")
    link = p.add_argument_group("transports (default: px4 → UDP 14580→14540, ardupilot → TCP 5760)")
    link.add_argument("--udp-local", type=int, metavar="PORT", help="bind UDP on 127.0.0.1:PORT (0 = ephemeral)")
    link.add_argument("--udp-remote", metavar="HOST:PORT",
                      help=f"where the UDP link sends before a client talks to it (default {DEFAULT_UDP_REMOTE}); "
                      "'none' to only answer senders")
    link.add_argument("--no-udp", action="store_true", help="disable UDP")
    link.add_argument("--tcp", type=int, metavar="PORT", help="TCP server on 127.0.0.1:PORT (0 = ephemeral)")
    link.add_argument("--no-tcp", action="store_true", help="disable TCP")
    clock = p.add_argument_group("time")
    clock.add_argument("--speed", type=float, default=1.0, help="× real time (default 1)")
    clock.add_argument("--lockstep", action="store_true",
                       help="advance one --lockstep-dt per received setpoint (SET_POSITION_TARGET_LOCAL_NED / "
                       "SET_ATTITUDE_TARGET)")
    clock.add_argument("--lockstep-dt", type=float, default=0.004, metavar="S", help="seconds per setpoint (default 0.004)")
    clock.add_argument("--duration", type=float, metavar="S", help="stop after S seconds of simulated time")
    clock.add_argument("--ekf-delay", type=float, default=0.5, metavar="S",
                       help="position estimate ready after S simulated seconds (default 0.5)")
    p.add_argument("--spawn", default="ground",
                   help="ground | hover:x,y,z | throw:x,y,z,vx,vy,vz[,qw,qx,qy,qz,p,q,r] — NED metres and m/s (z = "
                        "-altitude); a throw's optional attitude (body FRD to NED quaternion) and body rates (FRD rad/s)")
    p.add_argument("--home", metavar="LAT,LON,ALT",
                   help="home = EKF origin: WGS-84 degrees and metres AMSL (default 47.397742,8.545594,488, PX4 SITL's); "
                   "sent as HOME_POSITION and GPS_GLOBAL_ORIGIN; south / west: --home=-35.363261,149.16523,584")
    p.add_argument("--seed", type=int, default=0, help="seed of every random draw (faults, wind turbulence)")
    f = p.add_argument_group("fault injection (times in simulated seconds)")
    f.add_argument("--loss", type=float, default=0.0, metavar="PCT", help="drop this %% of datagrams (both directions)")
    f.add_argument("--duplicate", type=float, default=0.0, metavar="PCT", help="send this %% of datagrams twice")
    f.add_argument("--corrupt", type=float, default=0.0, metavar="PCT",
                   help="flip a byte in this %% of sent datagrams (CRC fails at the receiver)")
    f.add_argument("--latency", type=float, default=0.0, metavar="MS", help="delay sent datagrams by MS milliseconds")
    f.add_argument("--jitter", type=float, default=0.0, metavar="MS", help="plus uniform 0..MS ms")
    f.add_argument("--blackout", metavar="T0,T1", help="send nothing for T0 <= t < T1")
    f.add_argument("--windows-from-offboard", action="store_true",
                   help="--blackout times count from the first entry into OFFBOARD / GUIDED, not from boot")
    f.add_argument("--loss-from-offboard", action="store_true",
                   help="--loss only from the first entry into OFFBOARD / GUIDED (connecting is not under test)")
    f.add_argument("--estimator-reset", metavar="T[,dx,dy,dz]",
                   help="position estimate jumps by (dx,dy,dz) NED m at T (default 2,-1,0); reset_counter+1")
    f.add_argument("--takeover", metavar="T[,MODE]",
                   help="operator switches mode at T (default POSCTL for px4, LOITER for ardupilot)")
    f.add_argument("--gust", metavar="T,vn,ve,vd[,DUR]", help="(1-cos) wind gust NED m/s at T lasting DUR s (default 1)")
    p.add_argument("--signing-key", metavar="FILE",
                   help="MAVLink 2 signing: sign what is sent, drop unsigned / wrongly signed frames "
                   "(FILE: 32 raw bytes, 64 hex digits or a passphrase hashed with SHA-256)")
    p.add_argument("--truth-log", metavar="CSV", help="write the true vehicle state at every autopilot step")
    p.add_argument("--print-ports", action="store_true", help='print {"udp": port, "tcp": port} as JSON on stdout first')
    p.add_argument("--bench", action="store_true", help="print simulation-speed benchmarks and exit")
    p.add_argument("--quick", action="store_true", help="with --bench: fewer samples")
    p.add_argument("--json", action="store_true", help="with --bench: one JSON object")
    return p


def config_from_args(args: argparse.Namespace) -> MockConfig:
    """Translate parsed flags into a validated :class:`MockConfig` (MockConfigError on bad input)."""
    px4 = args.profile == "px4"
    udp_on = not args.no_udp and (args.udp_local is not None or (px4 and args.tcp is None))
    tcp_on = not args.no_tcp and (args.tcp is not None or (not px4 and args.udp_local is None))
    udp_remote: tuple[str, int] | None = None
    if udp_on:
        if args.udp_remote is None:
            udp_remote = _host_port(DEFAULT_UDP_REMOTE, "--udp-remote")
        elif args.udp_remote.lower() != "none":
            udp_remote = _host_port(args.udp_remote, "--udp-remote")
    if args.lockstep and args.speed != 1.0:
        raise MockConfigError("--speed", "cannot be combined with --lockstep")
    if not (args.lockstep_dt > 0 and math.isfinite(args.lockstep_dt)):
        raise MockConfigError("--lockstep-dt", f"must be > 0, got {args.lockstep_dt}")
    for flag, value in (("--latency", args.latency), ("--jitter", args.jitter)):
        if not (math.isfinite(value) and value >= 0):
            raise MockConfigError(flag, f"must be >= 0 ms, got {value}")
    faults = FaultConfig(
        loss=_percent(args.loss, "--loss"),
        duplicate=_percent(args.duplicate, "--duplicate"),
        corrupt=_percent(args.corrupt, "--corrupt"),
        latency_s=args.latency / 1000.0,
        jitter_s=args.jitter / 1000.0,
    )
    changes: dict[str, object] = {}
    if args.blackout:
        t0, t1 = _floats(args.blackout, 2, "--blackout")
        changes["blackout_s"] = (t0, t1)
    if args.windows_from_offboard:
        changes["windows_from_offboard"] = True
    if args.loss_from_offboard:
        changes["loss_from_offboard"] = True
    if args.estimator_reset:
        values = _floats(args.estimator_reset, None, "--estimator-reset")
        if len(values) not in (1, 4):
            raise MockConfigError("--estimator-reset", "expected T or T,dx,dy,dz")
        changes["estimator_reset_at_s"] = values[0]
        if len(values) == 4:
            changes["estimator_reset_ned_m"] = values[1:]
    if args.takeover:
        when, _, mode = args.takeover.partition(",")
        changes["takeover_at_s"] = _floats(when, 1, "--takeover")[0]
        if mode:
            from sitl_mock.profiles import PROFILES

            names = [m.name for m in PROFILES[args.profile].modes]
            if mode not in names:
                raise MockConfigError("--takeover", f"mode {mode!r} unknown for {args.profile}; one of {names}")
            changes["takeover_mode"] = mode
    if args.gust:
        values = _floats(args.gust, None, "--gust")
        if len(values) not in (4, 5):
            raise MockConfigError("--gust", "expected T,vn,ve,vd[,DUR]")
        changes["gust_at_s"] = values[0]
        changes["gust_ned_m_s"] = values[1:4]
        if len(values) == 5:
            changes["gust_duration_s"] = values[4]
    if changes:
        from dataclasses import replace

        faults = replace(faults, **changes)  # type: ignore[arg-type]
    wind: dict[str, object] = {}
    if args.wind is not None:
        values = _floats(args.wind, None, "--wind")
        if len(values) not in (2, 3):
            raise MockConfigError("--wind", f"expected VN,VE or VN,VE,VD (NED m/s), got {args.wind!r}")
        wind["wind_ned_m_s"] = (values + (0.0,))[:3]
    if args.wind_gusts is not None:
        values = _floats(args.wind_gusts, None, "--wind-gusts")
        if len(values) not in (1, 2):
            raise MockConfigError("--wind-gusts", f"expected STD or STD,TAU, got {args.wind_gusts!r}")
        wind["wind_gust_std_m_s"] = values[0]
        if len(values) == 2:
            wind["wind_gust_time_constant_s"] = values[1]
    try:
        MockConfig(**wind).validate()  # type: ignore[arg-type]
    except MockConfigError as exc:  # name the flag, not the field
        flag = "--wind" if exc.field == "wind_ned_m_s" else "--wind-gusts"
        raise MockConfigError(flag, exc.reason) from None
    home: dict[str, float] = {}
    if args.home:
        lat, lon, alt = _floats(args.home, 3, "--home")
        if not (abs(lat) <= 90.0 and abs(lon) <= 180.0 and -1000.0 <= alt <= 10000.0):
            raise MockConfigError("--home", f"need LAT in [-90, 90] deg, LON in [-180, 180] deg, ALT in [-1000, 10000] m AMSL, got {args.home!r}")
        home = {"home_lat_deg": lat, "home_lon_deg": lon, "home_alt_m": alt}
    params: list[tuple[str, float]] = []
    for item in args.param:
        name, sep, text = item.partition("=")
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not sep or not name or not math.isfinite(value):
            raise MockConfigError("--param", f"expected NAME=VALUE (a finite number), got {item!r}")
        params.append((name.strip(), value))
    config = MockConfig(
        **home,  # type: ignore[arg-type]
        profile=args.profile,
        vehicle=args.vehicle,
        spawn=SpawnSpec.parse(args.spawn),
        seed=args.seed,
        udp_local_port=(args.udp_local if args.udp_local is not None else DEFAULT_UDP_LOCAL) if udp_on else None,
        udp_remote=udp_remote,
        tcp_port=(args.tcp if args.tcp is not None else DEFAULT_TCP) if tcp_on else None,
        speed=args.speed,
        lockstep=args.lockstep,
        lockstep_dt_s=args.lockstep_dt,
        ekf_ready_delay_s=args.ekf_delay,
        faults=faults,
        duration_s=args.duration,
        truth_log=args.truth_log,
        **wind,  # type: ignore[arg-type]
        signing_key_file=args.signing_key,
        params=tuple(params),
    )
    config.validate()
    return config


def _describe(config: MockConfig, ports: object) -> str:
    parts = [f"sitl-mock: {config.profile} / {config.vehicle}"]
    udp, tcp = getattr(ports, "udp"), getattr(ports, "tcp")
    if udp is not None:
        remote = f" -> {config.udp_remote[0]}:{config.udp_remote[1]}" if config.udp_remote else ""
        parts.append(f"UDP 127.0.0.1:{udp}{remote}")
    if tcp is not None:
        parts.append(f"TCP 127.0.0.1:{tcp}")
    parts.append(f"lockstep {config.lockstep_dt_s} s/setpoint" if config.lockstep else f"speed {config.speed}x")
    if config.signing_key_file:
        parts.append("MAVLink 2 signing on")
    return ", ".join(parts)


async def _serve(config: MockConfig, print_ports: bool) -> None:
    from sitl_mock.server import MockAutopilot

    async with MockAutopilot(config) as mock:
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGTERM, signal.SIGINT):
            # Stop cleanly (sockets closed, truth log flushed) when terminated, e.g. by spawn().stop().
            loop.add_signal_handler(sig, mock.request_stop)
        if print_ports:
            print(json.dumps({"udp": mock.ports.udp, "tcp": mock.ports.tcp}), flush=True)
        print(_describe(config, mock.ports), file=sys.stderr, flush=True)
        await mock.wait_done()


def _bench(quick: bool, as_json: bool) -> int:
    from sitl_mock.bench_lockstep import run_lockstep

    results: dict[str, dict[str, object]] = {}
    try:
        from sitl_mock.dynamics.bench import run_inprocess

        results["sim"] = run_inprocess(quick=quick)
    except ImportError as exc:
        results["sim"] = {"error": str(exc)}
    results["mavlink"] = run_lockstep(quick=quick)
    if as_json:
        print(json.dumps(results, indent=2, sort_keys=True))
        return 0
    for section, figures in results.items():
        print(f"[{section}]")
        for key, value in figures.items():
            shown = f"{value:.4g}" if isinstance(value, float) else str(value)
            print(f"  {key:<40} {shown}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.bench:
        return _bench(args.quick, args.json)
    try:
        config = config_from_args(args)
    except MockConfigError as exc:
        print(f"sitl-mock: error: {exc}", file=sys.stderr)
        return 2
    try:
        asyncio.run(_serve(config, args.print_ports))
    except KeyboardInterrupt:
        return 0
    except OSError as exc:
        print(f"sitl-mock: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
