#!/usr/bin/env python3
"""Regenerate docs/evaluation.md and docs/figures/evaluation_push.png: path following vs
trajectory tracking on the paper path, from in-process ``sim`` flights on the realistic mock
preset (see pf_offboard/sim/evaluation.py for what is flown and measured):

    PYTHONPATH=. python scripts/evaluate.py

Deterministic (fixed seed and epoch): the same code gives the same document.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pf_offboard.sim.evaluation import main  # noqa: E402

if __name__ == "__main__":
    raise SystemExit(main())
