"""``pf-offboard bench``: speed figures (printed, or ``--json``), never timing assertions in tests.

Sections:
- ``startup``: wall time of ``pf-offboard --help`` / ``--version`` in a fresh interpreter (median)
  and which heavy modules (numpy, scipy, pymavlink, ...) they imported (none expected).
- ``core``: cost of ``PathFollower.update()`` on the paper path (median, p99 µs).
- ``sim``: in-process simulation speed of the sitl_mock dynamics (× real time at 1 kHz physics).
- ``mavlink``: lockstep simulation speed over loopback MAVLink with a client in the loop (× real
  time), and the app's state-in → setpoint-out latency (median, p99 ms at 250 Hz).
- ``memory``: resident memory of ``sim`` and ``fly`` over an hour of simulated time (``--quick``:
  10 minutes; ``--minutes N``: N): RSS after 1 simulated minute, at the end, growth in percent.
- ``sweep``: ``pf-offboard sweep`` flights serially, on 2 local worker processes and on Dask in
  local mode (speed-ups), and the CPU cost of writing each flight's logs (``--quick``: 8 flights).
"""

from __future__ import annotations

import argparse
import importlib
import json
from collections.abc import Callable
from typing import Any

# section -> (module, function) returning a flat dict of figures; imported only when run.
SECTIONS: tuple[tuple[str, str, str], ...] = (
    ("startup", "pf_offboard.bench.startup", "run"),
    ("core", "pf_offboard.bench.core", "run"),
    ("sim", "sitl_mock.dynamics.bench", "run_inprocess"),
    ("mavlink", "sitl_mock.bench_lockstep", "run_lockstep"),
    ("latency", "pf_offboard.bench.latency", "run"),
    ("memory", "pf_offboard.bench.memory", "run"),
    ("sweep", "pf_offboard.bench.sweep", "run"),
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--only",
        choices=[name for name, _, _ in SECTIONS],
        action="append",
        help="run only this section (repeatable); default: all but memory (an hour of simulated flight) and sweep",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    parser.add_argument("--quick", action="store_true", help="fewer samples (smoke run)")
    parser.add_argument("--minutes", type=_minutes, default=None, metavar="N",
                        help="memory: simulated minutes per flight (default 60, --quick 10; at least 2)")


def _minutes(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a number of minutes expected, got {text!r}") from None
    if not (2.0 <= value <= 24 * 60):  # the reference sample is taken after 1 simulated minute
        raise argparse.ArgumentTypeError(f"must be between 2 and 1440 minutes, got {text}")
    return value


def _section(module_name: str, func_name: str) -> Callable[..., dict[str, Any]]:
    return getattr(importlib.import_module(module_name), func_name)


# Long-running sections run only when asked for with --only (memory flies an hour of simulated time).
ON_REQUEST = ("memory", "sweep")


def run(args: argparse.Namespace) -> int:
    chosen = args.only or [name for name, _, _ in SECTIONS if name not in ON_REQUEST]
    results: dict[str, dict[str, Any]] = {}
    for name, module_name, func_name in SECTIONS:
        if name not in chosen:
            continue
        kwargs: dict[str, Any] = {"quick": args.quick}
        if name == "memory" and getattr(args, "minutes", None) is not None:
            kwargs["minutes"] = args.minutes
        results[name] = _section(module_name, func_name)(**kwargs)
        if not args.json:
            print(f"[{name}]")
            for key, value in results[name].items():
                shown = f"{value:.4g}" if isinstance(value, float) else str(value)
                print(f"  {key:<40} {shown}")
    if args.json:
        print(json.dumps(results, indent=2, sort_keys=True))
    return 0
