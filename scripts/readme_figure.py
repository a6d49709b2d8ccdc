"""Draw the README's picture: the default config (only a path and a speed) flown in ``sim`` on the
``px4-sih`` mock vehicle, from a hover 1.5 m off the path. Writes docs/figures/overview.png.

    python scripts/readme_figure.py [--out docs/figures/overview.png]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "docs" / "figures" / "overview.png"))
    args = ap.parse_args()

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pf_offboard.config import load_config
    from pf_offboard.control import PathFollower
    from pf_offboard.logs.steplog import column, read_steplog
    from pf_offboard.sim.flight import SimSpec, simulate

    paper = yaml.safe_load((ROOT / "configs" / "paper.yaml").read_text())
    config = {"path": paper["path"], "speed_m_s": paper["speed_m_s"]}  # the default: a path and a speed
    with tempfile.TemporaryDirectory() as tmp:
        cfg = Path(tmp) / "field.yaml"
        cfg.write_text(yaml.safe_dump(config))
        simulate(cfg, SimSpec(start_enu_m=(1.5, -1.5, 2.0), vehicle="px4-sih", laps=2.0, seed=1), tmp)
        records = read_steplog(Path(tmp) / "flight.csv")
        path = PathFollower.from_config(load_config(cfg)).path
    lam = np.linspace(0.0, path.lam_max, 600)
    ref = np.array([path.eval(float(x)).sigma for x in lam])
    p = column(records, "position_enu_m")
    t = column(records, "time_s")
    t = t - t[0]
    err_cm = 100.0 * column(records, "cross_track_m")

    fig = plt.figure(figsize=(10.0, 3.8))
    grid = fig.add_gridspec(1, 2, width_ratios=(1.0, 1.5), wspace=0.25)
    ax = fig.add_subplot(grid[0], projection="3d")
    ax.plot(ref[:, 0], ref[:, 1], ref[:, 2], "k--", lw=1.2, label="path (spline through the way-points)")
    ax.plot(p[:, 0], p[:, 1], p[:, 2], color="C0", lw=1.2, label="flown (two laps)")
    wp = np.array(config["path"]["waypoints"], dtype=float)
    ax.scatter(wp[:, 0], wp[:, 1], wp[:, 2], color="k", s=12, depthshade=False, label="way-points")
    ax.scatter(*p[0], color="C3", s=20, depthshade=False, label="start (hover off the path)")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_zlabel("up (m)")
    ax.legend(fontsize=6, loc="upper left")
    a2 = fig.add_subplot(grid[1])
    a2.plot(t, err_cm, lw=1.0)
    a2.set_yscale("log")
    a2.set_xlabel("time (s)")
    a2.set_ylabel("distance from the path (cm)")
    a2.set_title("default config on the px4-sih mock vehicle (sim)", fontsize=9)
    a2.grid(True, which="both", alpha=0.3)
    fig.subplots_adjust(left=0.02, right=0.98, bottom=0.14, top=0.92)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    print(out)


if __name__ == "__main__":
    main()
