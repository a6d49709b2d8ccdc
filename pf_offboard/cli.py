"""``pf-offboard`` command line: one sub-command per user task.

Each sub-command lives in its own module exposing ``add_arguments(parser)`` and
``run(args) -> int``. Modules keep heavy imports (matplotlib, sockets) inside ``run`` so
``pf-offboard --help`` stays fast. Any :class:`~pf_offboard.errors.InputError` becomes one
line on stderr and exit code 2; nothing is sent to a vehicle after bad input.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from pf_offboard import __version__
from pf_offboard.errors import InputError

# (name, module, one-line help): a fixed table, not a registry that modules mutate.
COMMANDS: tuple[tuple[str, str, str], ...] = (
    ("demo", "pf_offboard.app.demo", "fly the paper path against an embedded sitl-mock over real MAVLink"),
    ("fly", "pf_offboard.app.fly", "follow a path on a PX4 / ArduPilot vehicle over MAVLink"),
    ("sim", "pf_offboard.sim.cli", "in-process flight of the controller against the sitl_mock dynamics"),
    ("sweep", "pf_offboard.sweep.cli", "many in-process sim flights from seeded random thrown starts, in parallel"),
    ("replay", "pf_offboard.logs.replay", "re-run the controller on a recorded flight and compare setpoints"),
    ("identify", "pf_offboard.identify.cli", "fit the vehicle's inner-loop response (vehicle: section) from logs or a short excitation"),
    ("plot", "pf_offboard.logs.plot", "paper-style figures (Figs. 4-9) from flight logs"),
    ("bench", "pf_offboard.bench", "benchmarks: controller cost, simulation speed, MAVLink latency"),
    ("configs", "pf_offboard.app.configs_cmd", "list the shipped configs (use a name with --config)"),
    ("init", "pf_offboard.app.init_cmd", "write a config of your own: a path and a speed (or a copy of a shipped config)"),
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="pf-offboard",
        description="Time-invariant quadrotor path following (Kumar & Gill) over MAVLink.",
    )
    version = f"pf-offboard {__version__}"
    parser.add_argument("--version", action="version", version=version)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, module_name, help_text in COMMANDS:
        module = importlib.import_module(module_name)
        p = sub.add_parser(name, help=help_text, description=help_text)
        module.add_arguments(p)
        p.add_argument("--version", action="version", version=version)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args._run(args))
    except InputError as exc:
        print(f"pf-offboard {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
