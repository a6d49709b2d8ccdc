"""``pf-offboard init NAME [--from CONFIG] [--out FILE]``: a config of your own to edit.

Without ``--from`` it writes the default: the paper's path and a speed, nothing else, so every
other field takes the default that flies (docs/reference/config.md). ``--from NAME`` copies a
shipped config (or a file) with its comments; when that config's gains need an ideal inner loop
(``paper``), ``init`` says so and what they need. It never overwrites a file (exit 2 without
``--force``), and what it writes is validated first.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pf_offboard.errors import InputError

HEADER = """\
# {name}: your config (written by `pf-offboard init`{source}).
# Every field not written here takes its default: docs/reference/config.md lists them with units
# and ranges. Check it without flying, then fly it (docs/getting-started.md):
#   pf-offboard sim --config {out} --laps 2 --out runs/{name}
#   pf-offboard fly --connect udpin:0.0.0.0:14540 --config {out} --takeoff 2 --laps 2
#
"""

DEFAULT_BODY = """\
path:
  closed: true            # a loop; false: stop and hold at the last way-point
  waypoints:              # ENU metres from the vehicle's local origin: x east, y north, z up
    - [0.0, -1.5, 2.0]
    - [-1.6, -0.1, 1.8]
    - [-0.7, 0.6, 3.6]
    - [0.95, 1.3, 2.35]
    - [-0.65, 2.0, 1.9]
    - [-0.7, 0.6, 3.6]
    - [0.5, -1.2, 2.35]
  # or a planning tool's file instead of waypoints:
  # file: field.plan                  # .plan | .waypoints | .csv | .geojson | .kml
  # altitude_reference: relative_home # or amsl
speed_m_s: 1.5            # along the path; the sign picks the direction
# Your vehicle's inner loop, fitted from any flight log (then the gains are derived from it):
#   pf-offboard identify FLIGHT.ulg --write-config {out}
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("name", metavar="NAME", help="name of the new config (written to NAME.yaml unless --out)")
    parser.add_argument("--from", dest="source", metavar="CONFIG",
                        help="start from a shipped config (or a file) instead of the default path and speed "
                             "(see pf-offboard configs)")  # fmt: skip
    parser.add_argument("--out", metavar="FILE", help="where to write (default ./NAME.yaml)")
    parser.add_argument("--force", action="store_true", help="overwrite an existing file")


def run(args: argparse.Namespace) -> int:
    from pf_offboard.config import load_config, parse_config_bytes
    from pf_offboard.control.tuning import real_vehicle_warning
    from pf_offboard.shipped import resolve_config

    name = str(args.name)
    if not name or "/" in name or name.startswith("."):
        raise InputError("NAME", f"{name!r} is not a plain name (use --out for a path)")
    out = Path(args.out) if args.out else Path(name if name.endswith((".yaml", ".yml")) else f"{name}.yaml")
    if out.exists() and not args.force:
        raise InputError("--out", f"{out} exists (pass --force to overwrite)")
    stem = Path(name).stem
    if args.source is None:
        body = DEFAULT_BODY.format(out=out)
        text = HEADER.format(name=stem, source="", out=out) + body
        config = parse_config_bytes(text.encode(), "<init>")
    else:
        source = resolve_config(args.source, "--from")
        config = load_config(source)  # never hand out a copy that does not load
        text = HEADER.format(name=stem, source=f' from "{source.stem}"', out=out) + source.read_text(encoding="utf-8")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise InputError("--out", f"cannot write {out}: {exc.strerror or exc}") from None
    load_config(out)
    caution = real_vehicle_warning(config.gains, config.vehicle, config.compensation.enabled)
    if caution:
        print(f"pf-offboard init: note: {out}: {caution}. Fly it on an ideal vehicle: pf-offboard sim --vehicle fast, "
              "sitl-mock --vehicle fast; or delete its gains:, vehicle: and compensation: sections for the default",
              file=sys.stderr)  # fmt: skip
    print(out)
    return 0
