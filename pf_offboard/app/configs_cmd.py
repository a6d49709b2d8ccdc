"""``pf-offboard configs``: the shipped configs, one per line: name and what it flies."""

from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--paths", action="store_true", help="also print where each file is installed")


def run(args: argparse.Namespace) -> int:
    from pf_offboard.shipped import shipped_configs

    configs = shipped_configs()
    width = max((len(c.name) for c in configs), default=0)
    for c in configs:
        line = f"{c.name:<{width}}  {c.description}"
        if args.paths:
            line += f"  [{c.path}]"
        print(line)
    print("use: pf-offboard fly --config NAME ...; pf-offboard init MYCONFIG --from NAME writes an editable copy")
    return 0
