"""Judge a SITL flight against the simulator's ground truth (see pf_offboard.logs.truth).

    python scripts/sitl_truth.py LOG_DIR --config CONFIG [--skip S]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pf_offboard.errors import InputError
from pf_offboard.logs import truth


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(truth.__doc__ or "").split("\n\n")[0])
    ap.add_argument("log_dir", type=Path, help="the flight's --log-dir (flight.tlog + flight.csv)")
    ap.add_argument("--config", required=True, help="the config flown (file or shipped name)")
    ap.add_argument("--skip", type=float, default=8.0, help="seconds after activation left out (default 8)")
    args = ap.parse_args(argv)
    try:
        r = truth.judge(args.log_dir, args.config, args.skip)
    except InputError as exc:
        print(f"sitl_truth: {exc}", file=sys.stderr)
        return 2
    print(truth.describe(r, args.skip))
    return 0


if __name__ == "__main__":
    sys.exit(main())
