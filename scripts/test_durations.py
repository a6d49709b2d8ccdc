"""Write tests/durations.json from a test run's `--durations=0` report.

    python -m pytest -q -n 2 --dist loadgroup --durations=0 | tee run.log
    python scripts/test_durations.py run.log

Each test's seconds (setup + call + teardown) go into tests/durations.json; tests/conftest.py
queues the work units of `--dist loadgroup` longest first from it, so that a long test does not
start last and leave the other worker idle. Order only: a stale or missing entry changes no result.
Tests shorter than MIN_S are left out (they count as 0, which is where they sort anyway).
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MIN_S = 0.5
LINE = re.compile(r"^\s*(\d+(?:\.\d+)?)s\s+(setup|call|teardown)\s+(\S+)\s*$")


def durations(text: str) -> dict[str, float]:
    seconds: dict[str, float] = {}
    for line in text.splitlines():
        m = LINE.match(line)
        if m:
            nodeid = m.group(3).split("@", 1)[0]  # xdist appends @group to grouped tests
            seconds[nodeid] = seconds.get(nodeid, 0.0) + float(m.group(1))
    return {k: round(v, 2) for k, v in sorted(seconds.items()) if v >= MIN_S}


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print("usage: python scripts/test_durations.py RUN_LOG (a pytest --durations=0 report)", file=sys.stderr)
        return 2
    try:
        found = durations(Path(argv[0]).read_text(errors="replace"))
    except OSError as exc:
        print(f"RUN_LOG: cannot read {argv[0]}: {exc.strerror}", file=sys.stderr)
        return 2
    if not found:
        print(f"RUN_LOG: no --durations lines in {argv[0]} (run pytest with --durations=0)", file=sys.stderr)
        return 2
    out = ROOT / "tests" / "durations.json"
    out.write_text(json.dumps(found, indent=0, sort_keys=True) + "\n")
    print(f"{out.relative_to(ROOT)}: {len(found)} tests, {sum(found.values()):.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
