"""Start-up cost of the command line: ``pf-offboard --help`` and ``--version`` (wall time of a
fresh interpreter, median of several runs) and whether they imported numpy / scipy / pymavlink."""

from __future__ import annotations

import statistics
import subprocess
import sys
import time
from typing import Any

HEAVY = ("numpy", "scipy", "pymavlink", "matplotlib", "yaml")
_PROBE = (
    "import sys, contextlib, io\n"
    "from pf_offboard.cli import main\n"
    "with contextlib.redirect_stdout(io.StringIO()):\n"
    "    try:\n"
    "        main([{flag!r}])\n"
    "    except SystemExit:\n"
    "        pass\n"
    "print(','.join(m for m in {heavy!r} if m in sys.modules))\n"
)


def _wall_s(args: list[str]) -> float:
    start = time.perf_counter()
    subprocess.run([sys.executable, *args], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - start


def run(quick: bool = False) -> dict[str, Any]:
    n = 3 if quick else 7
    out: dict[str, Any] = {}
    for flag in ("--help", "--version"):
        name = flag.strip("-")
        out[f"{name}_wall_s"] = statistics.median(_wall_s(["-m", "pf_offboard", flag]) for _ in range(n))
        probe = subprocess.run([sys.executable, "-c", _PROBE.format(flag=flag, heavy=HEAVY)], check=True, capture_output=True, text=True)
        out[f"{name}_heavy_imports"] = probe.stdout.strip() or "none"
    out["python_startup_wall_s"] = statistics.median(_wall_s(["-c", "pass"]) for _ in range(n))
    return out
