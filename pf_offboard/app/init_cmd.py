"""``pf-offboard init NAME [--from CONFIG] [--out FILE]``: an editable copy of a shipped config.

The copy keeps the shipped file's comments and gets a header saying where it came from and how
to fly it. It never overwrites an existing file (exit 2), and it is validated before writing.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from pf_offboard.errors import InputError

HEADER = """\
# {name}: your copy of the shipped config "{source}" (written by `pf-offboard init`).
# Edit freely: every field is described in docs/controller.md (section 4) and docs/paths.md.
# Units are in the field names (m, m/s, deg, hz). Check it without flying:
#   pf-offboard sim --config {out} --duration 20 --out runs/{name}
# Fly it (see docs/getting-started.md first):
#   pf-offboard fly --connect udpin:0.0.0.0:14540 --config {out} --takeoff
#
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("name", metavar="NAME", help="name of the new config (written to NAME.yaml unless --out)")
    parser.add_argument("--from", dest="source", default="paper", metavar="CONFIG",
                        help="shipped config (or file) to start from (default paper; see pf-offboard configs)")  # fmt: skip
    parser.add_argument("--out", metavar="FILE", help="where to write (default ./NAME.yaml)")
    parser.add_argument("--force", action="store_true", help="overwrite an existing file")


def run(args: argparse.Namespace) -> int:
    from pf_offboard.config import load_config
    from pf_offboard.shipped import resolve_config

    name = str(args.name)
    if not name or "/" in name or name.startswith("."):
        raise InputError("NAME", f"{name!r} is not a plain name (use --out for a path)")
    source = resolve_config(args.source, "--from")
    load_config(source)  # never hand out a copy that does not load
    out = Path(args.out) if args.out else Path(name if name.endswith((".yaml", ".yml")) else f"{name}.yaml")
    if out.exists() and not args.force:
        raise InputError("--out", f"{out} exists (pass --force to overwrite)")
    text = HEADER.format(name=Path(name).stem, source=Path(source).stem, out=out) + source.read_text(encoding="utf-8")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise InputError("--out", f"cannot write {out}: {exc.strerror or exc}") from None
    load_config(out)
    print(out)
    return 0
