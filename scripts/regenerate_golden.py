#!/usr/bin/env python3
"""Regenerate the golden flights in tests/data/ (and, with --figures, docs/figures/).

A golden flight is a ``pf-offboard sim`` flight of the app's pipeline against the mock autopilot,
stored as ``NAME.tlog.gz`` + ``NAME.csv.gz`` + ``NAME.yaml`` (the config flown, a snapshot so
that editing configs/ does not change the goldens). tests/logs/test_golden.py replays each one
and requires the recomputed setpoints to equal the recorded ones (<= 1e-9): any change of the
controller's behaviour fails those tests until this script is run again and the new goldens are
committed — on purpose, after checking the change is wanted:

    python scripts/regenerate_golden.py            # goldens
    python scripts/regenerate_golden.py --figures  # goldens and the paper-style figures in docs/

Everything is deterministic (fixed seed, fixed UNIX epoch, gzip without timestamps): running it
twice gives identical bytes.
"""

from __future__ import annotations

import argparse
import gzip
import shutil
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pf_offboard.sim.flight import SimSpec, simulate  # noqa: E402

DATA = ROOT / "tests" / "data"
FIGURES = ROOT / "docs" / "figures"
PAPER = ROOT / "configs" / "paper.yaml"
# The figures fly the paper's experiment as shipped: path, gains (6 Hz / 0.7, 4 Hz / 0.8), limits.
# Starts at rest use eta2_ref = -1.5 m/s (Figs. 4-6), thrown starts +1.5 m/s (Figs. 7-9).
FIGURE_CONFIG = PAPER
EPOCH_UNIX_S = 1_780_000_000.0  # fixed so the .tlog bytes do not depend on when this runs


@dataclass(frozen=True)
class Golden:
    name: str
    config: Path
    spec: SimSpec
    what: str


# Small on purpose (a few hundred kB in all): 50 Hz, a few seconds each.
GOLDENS: tuple[Golden, ...] = (
    Golden(
        "paper_hover_px4",
        PAPER,
        SimSpec(vehicle="fast", start_enu_m=(0.0, -1.5, 2.0), autopilot="px4", rate_hz=50.0, duration_s=8.0, seed=1, epoch_unix_s=EPOCH_UNIX_S),
        "paper path from hover at (0, -1.5, 2) m (PF1), PX4, acceleration setpoints",
    ),
    Golden(
        "paper_throw_px4",
        PAPER,
        SimSpec(vehicle="fast", throw_enu=(1.0, -2.0, 1.2, 0.5, 1.0, 5.0), throw_height_m=2.0, autopilot="px4", rate_hz=50.0,
                duration_s=6.0, seed=2, epoch_unix_s=EPOCH_UNIX_S),  # fmt: skip
        "paper path, thrown from (1, -2, 1.2) m at (0.5, 1, 5) m/s, activation at 2 m, PX4",
    ),
    Golden(
        "paper_hover_ardupilot",
        PAPER,
        SimSpec(vehicle="fast", start_enu_m=(0.0, -1.5, 2.0), autopilot="ardupilot", output_mode="attitude", rate_hz=50.0,
                duration_s=6.0, seed=3, epoch_unix_s=EPOCH_UNIX_S),  # fmt: skip
        "paper path from hover, ArduPilot GUIDED, attitude + thrust setpoints",
    ),
)

# docs/figures: PF1 and four more start points at rest (Fig. 4), PF1's states (Figs. 5, 6);
# thrown starts (Fig. 7) and one thrown run's states (Figs. 8, 9). eta2_ref as in the config.
FIGURE_HOVER_STARTS = {
    "PF1": (0.0, -1.5, 2.0),
    "PF2": (1.5, 1.5, 1.5),
    "PF3": (-2.0, 1.5, 3.0),
    "PF4": (-1.0, -2.5, 1.2),
    "PF5": (1.8, -0.5, 3.2),
}
FIGURE_THROWS = {
    "PF1": (0.5, -2.0, 1.0, 0.0, 1.0, 5.5),
    "PF2": (-1.5, 1.0, 1.2, 1.5, 0.0, 5.0),
    "PF3": (1.5, 1.0, 1.0, -1.0, -1.5, 6.0),
    "PF4": (0.0, 0.0, 1.5, 2.5, 0.5, 8.0),
    "PF5": (-2.0, -1.0, 1.0, 2.0, 2.0, 9.5),
}
# Activation heights as in the paper's Fig. 7: 2 m for PF1-PF3, 4 m for PF4 and PF5.
FIGURE_THROW_HEIGHTS_M = {"PF1": 2.0, "PF2": 2.0, "PF3": 2.0, "PF4": 4.0, "PF5": 4.0}
FIGURE_DURATION_S = 12.0


def _gzip(src: Path, dst: Path) -> None:
    # mtime=0 and no file name in the header: identical bytes on every run
    with src.open("rb") as fin, dst.open("wb") as raw, gzip.GzipFile(filename="", mode="wb", fileobj=raw, mtime=0) as out:
        shutil.copyfileobj(fin, out)


def regenerate_goldens(out_dir: Path = DATA) -> list[Path]:
    out_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    with tempfile.TemporaryDirectory() as tmp:
        for g in GOLDENS:
            result = simulate(g.config, g.spec, Path(tmp) / g.name)
            for src, ext in ((result.paths.tlog, ".tlog.gz"), (result.paths.steps_csv, ".csv.gz")):
                dst = out_dir / f"{g.name}{ext}"
                _gzip(src, dst)
                written.append(dst)
            shutil.copyfile(result.paths.config_yaml, out_dir / f"{g.name}.yaml")
            written.append(out_dir / f"{g.name}.yaml")
            print(f"{g.name}: {g.what}; {len(result.records)} steps, {result.reason}")
    return written


def regenerate_figures(out_dir: Path = FIGURES, config: Path = FIGURE_CONFIG) -> list[Path]:
    from pf_offboard.logs.plot import make_figures

    import yaml

    out_dir.mkdir(parents=True, exist_ok=True)
    pngs: list[Path] = []
    with tempfile.TemporaryDirectory() as tmp:
        # The paper's thrown runs travel the other way round (eta2_ref = +1.5 m/s, Fig. 7).
        data = yaml.safe_load(config.read_text())
        data["speed_m_s"] = abs(float(data["speed_m_s"]))
        throw_config = Path(tmp) / "throw.yaml"
        throw_config.write_text(yaml.safe_dump(data, sort_keys=False))
        for group, starts in (("hover", FIGURE_HOVER_STARTS), ("throw", FIGURE_THROWS)):
            group_config = config if group == "hover" else throw_config
            logs = []
            for name, start in starts.items():
                spec = SimSpec(vehicle="fast", 
                    start_enu_m=start if group == "hover" else None,  # type: ignore[arg-type]
                    throw_enu=start if group == "throw" else None,
                    throw_height_m=FIGURE_THROW_HEIGHTS_M[name] if group == "throw" else 2.0,
                    duration_s=FIGURE_DURATION_S,
                    epoch_unix_s=EPOCH_UNIX_S,
                    name=name,
                )
                result = simulate(group_config, spec, Path(tmp) / group)
                print(f"figures/{group}/{name}: {result.reason}; " + "; ".join(result.summary.lines()[1:3]))
                logs.append(result.paths.steps_csv)
            figs = Path(tmp) / f"fig-{group}"
            title = "Start at rest (cf. Fig. 4)" if group == "hover" else "Thrown starts, activation at 2 m / 4 m (cf. Fig. 7)"
            make_figures(logs, figs, group_config, title=title)
            detail = "PF1" if group == "hover" else "PF5"  # the paper details PF1 (Figs. 5, 6) and thrown PF5 (8, 9)
            for src, dst in (
                ("path3d.png", f"{group}_path3d.png"),
                (f"{detail}_tangential.png", f"{group}_{detail}_tangential.png"),
                (f"{detail}_transversal.png", f"{group}_{detail}_transversal.png"),
            ):
                shutil.copyfile(figs / src, out_dir / dst)
                pngs.append(out_dir / dst)
    return pngs


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--figures", action="store_true", help="also regenerate docs/figures/*.png")
    parser.add_argument("--only-figures", action="store_true", help="regenerate docs/figures/*.png only")
    args = parser.parse_args(argv)
    if not args.only_figures:
        for p in regenerate_goldens():
            print(f"  {p.relative_to(ROOT)} ({p.stat().st_size / 1000:.0f} kB)")
    if args.figures or args.only_figures:
        for p in regenerate_figures():
            print(f"  {p.relative_to(ROOT)} ({p.stat().st_size / 1000:.0f} kB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
