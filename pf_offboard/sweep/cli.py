"""``pf-offboard sweep``: many in-process ``sim`` flights from random thrown starts, in parallel.

Writes ``OUT/flights.csv`` (and ``.parquet`` with pyarrow), ``OUT/summary.json``, ``OUT/roa.png``;
with ``--gains``, ``OUT/gains.csv`` (candidates ranked) and ``OUT/best-gains.yaml``.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from pf_offboard.sweep.plan import SweepSpec


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from sitl_mock.dynamics.params import PRESET_NAMES

    from pf_offboard.sweep.runner import FlightSettings
    from pf_offboard.sweep.starts import StartRanges

    r, f = StartRanges(), FlightSettings()
    parser.add_argument("--config", required=True, metavar="YAML", help="config file, or a shipped config's name")
    parser.add_argument("--out", required=True, metavar="DIR", help="directory for flights.csv, summary.json, roa.png")
    parser.add_argument("--flights", type=int, default=100, metavar="N", help="number of random starts (default 100)")
    parser.add_argument("--seed", type=int, default=0, help="seed: flight i's start depends only on (seed, i) (default 0)")
    parser.add_argument("--workers", type=int, default=1, metavar="W",
                        help="local worker processes (default 1: in this process); with --cluster local, its workers")
    parser.add_argument("--cluster", metavar="ADDRESS",
                        help="run on Dask: a scheduler address (tcp://host:8786) or 'local' (a LocalCluster of --workers "
                        "processes); needs pip install 'pf-offboard[cluster]'")
    parser.add_argument("--engine", choices=("batch", "scalar"), default="batch",
                        help="batch (default): many flights per process stepped as arrays, the same rows as scalar; "
                        "scalar: one flight at a time (the reference; flights batch does not mirror always fly so)")
    g = parser.add_argument_group("flights")
    g.add_argument("--vehicle", default=f.vehicle, metavar="PRESET[,PRESET...]",
                   help=f"simulated airframe, one of {', '.join(PRESET_NAMES)} (default {f.vehicle}); several (comma-separated): "
                   "every start (and gain candidate) flies on each, ranked per vehicle")
    g.add_argument("--autopilot", choices=("px4", "ardupilot"), default=f.autopilot, help="mock autopilot profile (default px4)")
    g.add_argument("--output", choices=("acceleration", "attitude", "rates"), help="setpoint type (default: config)")
    g.add_argument("--rate", type=float, metavar="HZ", help="control/telemetry rate (default: config)")
    g.add_argument("--duration", type=float, default=f.duration_s, metavar="S", help=f"simulated seconds per flight (default {f.duration_s:g})")
    g.add_argument("--tube", type=float, default=f.tube_m, metavar="M",
                   help=f"caught: the first time the cross-track is <= M (default {f.tube_m:g})")
    g.add_argument("--stay", type=float, default=f.stay_m, metavar="M",
                   help=f"a success keeps the cross-track <= M from being caught to the end (default {f.stay_m:g})")
    g.add_argument("--speed-tol", type=float, metavar="M_S", help="caught also needs |eta2 - eta2_ref| <= M_S (default: not judged)")
    g.add_argument("--settle", type=float, default=f.settle_s, metavar="S",
                   help=f"a success was caught at least S before the end (default {f.settle_s:g})")
    g.add_argument("--keep-logs", action="store_true", help="write every flight's .tlog/.csv under OUT/flights/ (slower)")
    s = parser.add_argument_group("random starts (thrown: the controller engages at the drawn state)")
    s.add_argument("--max-distance", type=float, default=r.max_distance_m, metavar="M", help=f"from the path (default {r.max_distance_m:g})")
    s.add_argument("--max-speed", type=float, default=r.max_speed_m_s, metavar="M_S", help=f"(default {r.max_speed_m_s:g})")
    s.add_argument("--max-tilt", type=float, default=r.max_tilt_deg, metavar="DEG", help=f"from level (default {r.max_tilt_deg:g})")
    s.add_argument("--max-rate", type=float, default=r.max_rate_rad_s, metavar="RAD_S", help=f"body rates (default {r.max_rate_rad_s:g})")
    s.add_argument("--max-wind", type=float, default=r.max_wind_m_s, metavar="M_S", help=f"horizontal wind (default {r.max_wind_m_s:g})")
    s.add_argument("--min-height", type=float, default=r.min_height_m, metavar="M", help=f"lowest start (default {r.min_height_m:g})")
    k = parser.add_argument_group("gain sweep (rank (bandwidth, damping) pairs, both loops, on the same starts)")
    k.add_argument("--gains", choices=("grid", "random"), help="sweep gains: a grid or random candidates")
    k.add_argument("--bandwidth", metavar="LO:HI", help="bandwidth range, Hz (default: 0.5..1.5 x the config's transversal)")
    k.add_argument("--damping", metavar="LO:HI", default="0.6:1.2", help="damping range (default 0.6:1.2)")
    k.add_argument("--gain-points", type=int, default=3, metavar="N", help="grid: N per axis (N^2 candidates); random: N (default 3)")
    parser.add_argument("--no-plot", action="store_true", help="skip roa.png")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def _spec(args: argparse.Namespace) -> SweepSpec:
    from pf_offboard.config import load_config
    from pf_offboard.sweep import gains as gains_mod
    from pf_offboard.sweep.plan import SweepSpec
    from pf_offboard.sweep.runner import FlightSettings
    from pf_offboard.sweep.starts import StartRanges

    from sitl_mock.dynamics.params import PRESET_NAMES

    from pf_offboard.errors import InputError as _InputError

    vehicles = tuple(v.strip() for v in str(args.vehicle).split(","))
    for v in vehicles:
        if v not in PRESET_NAMES:
            raise _InputError("--vehicle", f"unknown vehicle {v!r}; choose from {', '.join(PRESET_NAMES)}")
    if len(set(vehicles)) != len(vehicles):
        raise _InputError("--vehicle", f"a vehicle given twice: {args.vehicle}")
    ranges = StartRanges(max_distance_m=args.max_distance, max_speed_m_s=args.max_speed, max_tilt_deg=args.max_tilt,
                         max_rate_rad_s=args.max_rate, max_wind_m_s=args.max_wind, min_height_m=args.min_height)
    settings = FlightSettings(vehicle=vehicles[0], autopilot=args.autopilot, output_mode=args.output, duration_s=args.duration,
                              rate_hz=args.rate, tube_m=args.tube, stay_m=args.stay, speed_tol_m_s=args.speed_tol,
                              settle_s=args.settle)  # fmt: skip
    cands: tuple[gains_mod.GainCandidate, ...] = ()
    if args.gains is not None:
        if args.bandwidth is None:
            bw = load_config(args.config).gains.transversal_bandwidth_hz
            bandwidth = (max(0.5 * bw, gains_mod.BANDWIDTH_HZ[0]), min(1.5 * bw, gains_mod.BANDWIDTH_HZ[1]))
        else:
            bandwidth = gains_mod.parse_range(args.bandwidth, "--bandwidth", gains_mod.BANDWIDTH_HZ)
        damping = gains_mod.parse_range(args.damping, "--damping", gains_mod.DAMPING)
        cands = tuple(gains_mod.candidates(args.gains, bandwidth, damping, args.gain_points, args.seed))
    else:
        from pf_offboard.errors import InputError

        for flag, given in (("--bandwidth", args.bandwidth is not None), ("--gain-points", args.gain_points != 3),
                            ("--damping", args.damping != "0.6:1.2")):  # fmt: skip
            if given:
                raise InputError(flag, "only a gain sweep (--gains grid|random) takes it")
    return SweepSpec(args.flights, args.seed, ranges, settings, cands, vehicles if len(vehicles) > 1 else ()).validate()


def run(args: argparse.Namespace) -> int:
    import os
    from pathlib import Path

    from pf_offboard.logs._io import make_dir
    from pf_offboard.shipped import resolve_config
    from pf_offboard.sweep import plan, report
    from pf_offboard.sweep.runner import Progress, check_workers

    args.config = str(resolve_config(args.config))
    if args.cluster is not None:
        from pf_offboard.sweep.engine import check_address

        check_address(args.cluster)
    check_workers(args.workers)
    spec = _spec(args)
    out = Path(make_dir(args.out, "--out"))
    logs_dir = out / "flights" if args.keep_logs else None
    progress = None if args.quiet else Progress(spec.total_flights)
    with report.Journal(out / report.JOURNAL_CSV) as journal:

        def on_row(row: dict[str, object]) -> None:
            journal(row)
            if progress is not None:
                progress(row)

        result = plan.run(args.config, spec, args.workers, args.cluster, on_row, logs_dir, engine=args.engine)
    files = report.write_table(result.rows, out)
    (out / report.JOURNAL_CSV).unlink()
    from dataclasses import asdict

    stats = report.summarize(result.rows, args.config, asdict(spec.settings))
    summary = {**stats, "wall_time_s": result.wall_s, "executor": result.executor, "engine": args.engine, "workers": args.workers,
               "cpu_count": os.cpu_count(), "load_average_at_end": list(os.getloadavg()), "config": args.config,
               "settings": plan.settings_dict(spec)}  # fmt: skip
    print(f"pf-offboard sweep: {len(result.rows)} flights in {result.wall_s:.1f} s ({args.engine} engine, {result.executor})")
    for line in report.lines(stats):
        print("  " + line)
    if spec.gains:
        from pf_offboard.sweep.gains import rank

        # several vehicles: one ranking per vehicle (gains-<vehicle>.csv, best-gains-<vehicle>.yaml)
        per_vehicle = [(f" on {v}", f"-{v}", [r for r in result.rows if r["vehicle"] == v]) for v in spec.vehicles] \
            if spec.vehicles else [("", "", result.rows)]  # fmt: skip
        for label, suffix, vrows in per_vehicle:
            ranking = rank(vrows, spec.gains)
            files += report.write_table(ranking, out, "gains" + suffix)
            best = next(c for c in spec.gains if c.id == ranking[0]["gains_id"])
            (out / f"best-gains{suffix}.yaml").write_text(plan.config_yaml(args.config, best), encoding="utf-8")
            summary["gain_ranking" + suffix.replace("-", "_")] = ranking
            print(f"  gains{label} (best first): " + "; ".join(
                f"#{r['rank']} {r['bandwidth_hz']:.3g} Hz / {r['damping']:.3g}: {100 * r['success_rate']:.0f} %, p90 "
                f"{r['caught_p90_s']:.2f} s" for r in ranking[:5]))  # fmt: skip
    report.write_json(summary, out / "summary.json")
    if not args.no_plot:
        title = f"{len(result.rows)} thrown starts, {spec.settings.vehicle}: {100 * stats['success_rate']:.1f} % caught"
        files.append(report.roa_plot(result.rows, out / "roa.png", title))
    print("files: " + " ".join(str(p) for p in [*files, out / "summary.json"]))
    return 1 if stats["failures_by_kind"].get("error") else 0
