"""``pf-offboard`` command line: one sub-command per user task.

Each sub-command lives in its own module exposing ``add_arguments(parser)`` and
``run(args) -> int``. Modules keep heavy imports (matplotlib, sockets) inside ``run`` so
``pf-offboard --help`` stays fast. Any :class:`~pf_offboard.errors.InputError` becomes one
line on stderr and exit code 2; nothing is sent to a vehicle after bad input.
"""

from __future__ import annotations

import argparse
import functools
import importlib
import sys
from collections.abc import Sequence
from typing import NoReturn

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


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (``--help`` shows the usage): bad input is one line, exit 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {_clip(message)} (--help for usage)\n")


def _clip(text: str, limit: int = 400) -> str:
    """A message for one line: no line breaks, a 5000-character argument cut in the middle."""
    text = " ".join(str(text).split())
    return text if len(text) <= limit else f"{text[: limit // 2]} ... {text[-limit // 2 :]}"


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser; only ``command``'s module is imported (None: every command's, e.g. for docs),
    so ``pf-offboard --help`` / ``--version`` import nothing heavy (measured in ``bench``)."""
    from pf_offboard import __version__

    parser = _Parser(
        prog="pf-offboard",
        description="Time-invariant quadrotor path following (Kumar & Gill) over MAVLink.",
    )
    version = f"pf-offboard {__version__}"
    parser.add_argument("--version", action="version", version=version)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, module_name, help_text in COMMANDS:
        p = sub.add_parser(name, help=help_text, description=help_text)
        p.add_argument("--version", action="version", version=version)
        if command is None or name == command:
            module = importlib.import_module(module_name)
            module.add_arguments(p)
            p.set_defaults(_run=module.run)
    return parser


@functools.lru_cache(maxsize=None)
def _parser_for(command: str) -> argparse.ArgumentParser:
    """:func:`build_parser`, built once per command in a process: ``main`` called many times in
    one process (the CLI fuzz test: 1100 command lines; an embedding script) no longer rebuilds
    the argparse tree each time (~2 ms, most of a refused command line's cost). Parsing does not
    change a parser (every default is copied into the new namespace), so one can serve every call."""
    return build_parser(command)


def main(argv: Sequence[str] | None = None) -> int:
    raw = list(sys.argv[1:] if argv is None else argv)
    first = next((a for a in raw if not a.startswith("-")), "")
    parser = _parser_for(first if first in {name for name, _, _ in COMMANDS} else "")
    empty = next((i for i, a in enumerate(raw) if a == "" or (a.startswith("--") and a.endswith("="))), None)
    if empty is not None:  # an empty value never means "the default": it is a mistake (an unset variable)
        after = f" after {_clip(raw[empty - 1])}" if empty > 0 and raw[empty] == "" else f" in {_clip(raw[empty])}"
        parser.error(f"empty argument{after}")
    args = parser.parse_args(raw)
    try:
        return int(args._run(args))
    except InputError as exc:
        print(f"pf-offboard {args.command}: error: {_clip(str(exc))}", file=sys.stderr)
        return 2
    except OSError as exc:
        if exc.filename is None:
            raise
        # a file or directory the user named could not be used (a name too long, a permission):
        # bad input, one line (each command turns the errors it expects into InputError itself)
        print(f"pf-offboard {args.command}: error: {_clip(str(exc.filename))}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
