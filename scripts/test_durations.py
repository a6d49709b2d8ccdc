"""Write tests/durations.json from a test run's per-test times.

    PF_OFFBOARD_TEST_TIMES=times python -m pytest -q -n 0
    python scripts/test_durations.py times

With PF_OFFBOARD_TEST_TIMES set, tests/conftest.py has each test process write the wall and CPU
seconds (setup + call + teardown; CPU with the subprocesses the test waited for) of every test it
ran to `times-<worker>.json` in that directory. Run it on one process (`-n 0`) on a quiet machine:
the times are then the tests' own, not the share of a core they got. tests/conftest.py queues the
work units of `--dist loadgroup` from the file: longest first, a computing unit and a mostly waiting
one in turn. Order only: a stale or missing entry changes no result. Tests shorter than MIN_S are
left out (they count as 0, which is where they sort anyway).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MIN_S = 0.5


def durations(times: dict[str, list[float]]) -> dict[str, list[float]]:
    """nodeid -> [wall s, CPU s], rounded, for the tests of at least MIN_S wall."""
    return {k: [round(v[0], 2), round(v[1], 2)] for k, v in sorted(times.items()) if v[0] >= MIN_S}


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print("usage: python scripts/test_durations.py TIMES_DIR (written by a run with PF_OFFBOARD_TEST_TIMES=TIMES_DIR)",
              file=sys.stderr)  # fmt: skip
        return 2
    directory = Path(argv[0])
    times: dict[str, list[float]] = {}
    files = sorted(directory.glob("times-*.json"))
    for f in files:
        try:
            data = json.loads(f.read_text())
        except (OSError, ValueError) as exc:
            print(f"TIMES_DIR: cannot read {f}: {exc}", file=sys.stderr)
            return 2
        if not isinstance(data, dict) or not all(isinstance(v, list) and len(v) == 2 for v in data.values()):
            print(f"TIMES_DIR: {f} is not a map of test -> [wall s, CPU s]", file=sys.stderr)
            return 2
        times.update(data)
    if not times:
        print(f"TIMES_DIR: no times-*.json with tests in {directory} (run pytest with PF_OFFBOARD_TEST_TIMES={directory})",
              file=sys.stderr)  # fmt: skip
        return 2
    found = durations(times)
    out = ROOT / "tests" / "durations.json"
    out.write_text("{\n" + ",\n".join(f"{json.dumps(k)}: {json.dumps(v)}" for k, v in found.items()) + "\n}\n")  # a test per line
    wall = sum(v[0] for v in found.values())
    cpu = sum(v[1] for v in found.values())
    print(f"{out.relative_to(ROOT)}: {len(found)} tests, {wall:.0f} s wall, {cpu:.0f} s CPU")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
