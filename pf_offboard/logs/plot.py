"""``pf-offboard plot``: the paper's figures (Kumar & Gill, Figs. 4-9) from flight logs.

- ``path3d.png`` — the reference path and every run's output trajectory with its start point
  (Figs. 4 and 7): the legend gives each run's start position, or its speed at activation for
  a thrown start;
- ``map.png`` — top view in the map frame (x east, y north, equal scale): reference path,
  tracks, the local origin and the geofence of the config's ``safety:`` section when it has one;
- ``<run>_tangential.png`` — η1 (arclength, m) and η2 (speed along the path, m/s) against time
  with η2_ref (Figs. 5 and 8);
- ``<run>_transversal.png`` — ξ1, φ1 (m) and ξ2, φ2 (m/s) against time (Figs. 6 and 9).

Inputs are step-log CSVs (``flight.csv``) or ``.tlog`` files with their sibling CSV. The
reference path comes from ``--config`` or the config copy beside the first log.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pf_offboard.errors import InputError
from pf_offboard.logs._io import make_dir
from pf_offboard.logs.flightlog import FlightLogPaths, log_stem
from pf_offboard.logs.steplog import StepRecord, column, read_steplog

_DPI = 110
_THROW_SPEED_M_S = 0.5  # a start faster than this is labelled by its speed, like Fig. 7


@dataclass(frozen=True)
class Run:
    """One flight's step log, ready to plot (times relative to the first record, s)."""

    name: str
    records: list[StepRecord]
    t_s: NDArray[np.float64]
    activation_s: tuple[float, ...]  # instants the follower was (re)activated, relative s

    @classmethod
    def from_records(cls, name: str, records: list[StepRecord]) -> Run:
        if not records:
            raise InputError(name, "step log has no rows")
        t = column(records, "time_s")
        t = t - t[0]
        act: list[float] = []
        prev = False
        for ti, r in zip(t, records):
            if r.active and not prev:  # setpoints start to fly: launch, throw trigger, re-engage
                act.append(float(ti))
            prev = r.active
        return cls(name, records, t, tuple(act))

    @property
    def first_active(self) -> int:
        """Index of the first active step (0 when the log never activates)."""
        return next((i for i, r in enumerate(self.records) if r.active), 0)

    def col(self, name: str) -> NDArray[np.float64]:
        return column(self.records, name)


def load_run(path: str | Path) -> Run:
    """A run from a step-log CSV, or from a ``.tlog`` through its sibling CSV."""
    p = Path(path)
    is_tlog = p.name.endswith((".tlog", ".tlog.gz"))
    csv_path = FlightLogPaths.beside(p).steps_csv if is_tlog else p
    if not csv_path.exists():
        raise InputError(str(p), f"no step log {csv_path.name} beside it (plot reads the per-step CSV)")
    stem = log_stem(p)
    # fly / sim name their logs "flight": the run is then known by its directory
    name = p.resolve().parent.name if stem == "flight" and p.resolve().parent.name else stem
    return Run.from_records(name, read_steplog(csv_path))


def _is_foreign(path: Path) -> bool:
    """A PX4 ULog, or a tlog without pf-offboard's step CSV beside it (a ground station's)."""
    if path.suffix.lower() == ".ulg":
        return True
    return path.name.endswith((".tlog", ".tlog.gz")) and not FlightLogPaths.beside(path).steps_csv.exists()


def load_runs(path: str | Path, config_path: Path | None) -> list[Run]:
    """The runs of one log: ours (its step CSV), or a ULog's / ground station's tlog's track(s)
    with the path coordinates computed against ``config_path``'s path."""
    p = Path(path)
    if not _is_foreign(p):
        return [load_run(p)]
    from pf_offboard.logs.foreign import read_foreign_tlog, read_ulog_tracks, step_records

    kind = "a PX4 ULog" if p.suffix.lower() == ".ulg" else "a ground station's tlog (no pf-offboard step log beside it)"
    if config_path is None:
        raise InputError(str(p), f"is {kind}: pass --config (the config that was flown) to plot it against its path")
    from pf_offboard.config import load_config
    from pf_offboard.control import PathFollower

    config = load_config(config_path).require_local("for a path from a planning tool, give path.origin")
    tracks = read_ulog_tracks(p) if p.suffix.lower() == ".ulg" else [read_foreign_tlog(p)]
    runs = []
    for track in tracks:
        records = step_records(track, PathFollower.from_config(config))
        runs.append(Run.from_records(track.name, records))
    return runs


def _start_label(run: Run) -> str:
    r = run.records[run.first_active]
    x, y, z = r.position_enu_m
    speed = float(np.linalg.norm(r.velocity_enu_m_s))
    if speed > _THROW_SPEED_M_S:
        return f"{run.name}: |v| = {speed:.1f} m/s at activation"
    return f"{run.name}: start ({x:.1f}, {y:.1f}, {z:.1f}) m"


def _waypoints(config_path: Path | None) -> NDArray[np.float64] | None:
    """The config's way-points (ENU m), to mark on the figures; None without a local path."""
    if config_path is None:
        return None
    from pf_offboard.config import load_config

    config = load_config(config_path)
    return np.asarray(config.path.waypoints_enu_m, dtype=float) if config.path.waypoints_enu_m else None


def _reference_path(config_path: Path | None) -> NDArray[np.float64] | None:
    if config_path is None:
        return None
    from pf_offboard.control import PathFollower  # the core; imported only when plotting a path

    from pf_offboard.config import load_config

    config = load_config(config_path).require_local("or plot with the flight.yaml beside the log: it holds the local way-points flown")
    path = PathFollower.from_config(config).path
    lam = np.linspace(0.0, path.lam_max, 600)
    return np.array([path.eval(float(x)).sigma for x in lam])


def _mark_activation(ax: object, run: Run, label: bool) -> None:
    for i, ta in enumerate(run.activation_s):
        ax.axvline(ta, color="0.4", ls=":", lw=1.0, label="activation" if (label and i == 0) else None)  # type: ignore[attr-defined]


def _break_wraps(eta1_m: NDArray[np.float64]) -> NDArray[np.float64]:
    """η1 of a closed path wraps at the path length: leave a gap there instead of a vertical line."""
    out = eta1_m.astype(float).copy()
    finite = out[np.isfinite(out)]
    if finite.size < 2:
        return out
    span = float(np.max(finite) - np.min(finite))
    jumps = np.flatnonzero(np.abs(np.diff(out)) > 0.5 * span)
    out[jumps] = np.nan
    return out


def _equal_aspect(ax: object, points: NDArray[np.float64]) -> None:
    """Metres look like metres: equal scale on x, y, z."""
    finite = points[np.all(np.isfinite(points), axis=1)]
    if finite.size == 0:
        return
    lo, hi = finite.min(axis=0), finite.max(axis=0)
    ax.set_box_aspect(np.maximum(hi - lo, 0.2 * float(np.max(hi - lo)) + 1e-6))  # type: ignore[attr-defined]


def plot_path3d(runs: Sequence[Run], reference: NDArray[np.float64] | None, out: Path, title: str,
                waypoints: NDArray[np.float64] | None = None) -> Path:  # fmt: skip
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(6.4, 5.2))
    ax = fig.add_subplot(projection="3d")
    if reference is not None:
        ax.plot(reference[:, 0], reference[:, 1], reference[:, 2], color="k", ls="--", lw=1.4, label="path to follow")
    if waypoints is not None:
        ax.scatter(waypoints[:, 0], waypoints[:, 1], waypoints[:, 2], color="k", marker="s", s=14, depthshade=False, label="way-points")
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, run in enumerate(runs):
        c = colors[k % len(colors)]
        p = run.col("position_enu_m")
        ax.plot(p[:, 0], p[:, 1], p[:, 2], color=c, lw=1.2, label=_start_label(run))
        ax.scatter(*p[0], color=c, marker="o", s=28, depthshade=False)
        if run.first_active > 0:
            ax.scatter(*p[run.first_active], color=c, marker="x", s=36, depthshade=False)
    pts = [run.col("position_enu_m") for run in runs] + ([reference] if reference is not None else [])
    _equal_aspect(ax, np.vstack(pts))
    ax.set_xlabel("east, x (m)")
    ax.set_ylabel("north, y (m)")
    ax.set_zlabel("up, z (m)")
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(out, dpi=_DPI)
    plt.close(fig)
    return out


@dataclass(frozen=True)
class Fence:
    """A geofence in the local ENU frame (m): a box (``min_enu_m`` / ``max_enu_m``) or a vertical
    cylinder (``center_enu_m`` (x, y), ``radius_m``), as in the config's ``safety:`` section."""

    min_enu_m: tuple[float, float, float] | None = None
    max_enu_m: tuple[float, float, float] | None = None
    center_enu_m: tuple[float, float] | None = None
    radius_m: float | None = None


def fence_from_config(config_path: Path | None) -> Fence | None:
    """The ``safety:`` fence of a config file (``fence_min_enu_m`` + ``fence_max_enu_m``, or
    ``fence_center_enu_m`` + ``fence_radius_m``), or None when it has none (read from the YAML, so
    a log's config copy draws the fence it was flown with)."""
    if config_path is None or not Path(config_path).is_file():
        return None
    import yaml

    try:
        data = yaml.safe_load(Path(config_path).read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError):
        return None
    safety = data.get("safety") if isinstance(data, dict) else None
    if not isinstance(safety, dict):
        return None

    def vec(name: str, n: int) -> tuple[float, ...] | None:
        v = safety.get(name)
        if isinstance(v, (list, tuple)) and len(v) == n and all(isinstance(x, (int, float)) for x in v):
            return tuple(float(x) for x in v)
        return None

    lo, hi = vec("fence_min_enu_m", 3), vec("fence_max_enu_m", 3)
    center, radius = vec("fence_center_enu_m", 2), safety.get("fence_radius_m")
    if lo is not None and hi is not None:
        return Fence(min_enu_m=lo, max_enu_m=hi)  # type: ignore[arg-type]
    if center is not None and isinstance(radius, (int, float)):
        return Fence(center_enu_m=center, radius_m=float(radius))  # type: ignore[arg-type]
    return None


def _origin_note(log_dir: Path) -> str:
    """``origin lat .. lon ..`` from the flight's summary.json when its path came from lat/lon."""
    import json

    try:
        report = json.loads((log_dir / "summary.json").read_text(encoding="utf-8"))
        o = report["path_file"]["origin"]
        return f"; origin {o['lat_deg']:.7f}, {o['lon_deg']:.7f}, {o['alt_amsl_m']:.1f} m AMSL"
    except (OSError, ValueError, KeyError, TypeError):
        return ""


def plot_map(runs: Sequence[Run], reference: NDArray[np.float64] | None, fence: Fence | None, out: Path, note: str = "",
             waypoints: NDArray[np.float64] | None = None) -> Path:  # fmt: skip
    """Top view in the map frame (x east, y north, metres; equal scale): the reference path,
    every run's track with its start (o) and activation (x), the local origin (+) and the fence."""
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Rectangle

    fig, ax = plt.subplots(figsize=(6.4, 6.0))
    if fence is not None and fence.min_enu_m is not None and fence.max_enu_m is not None:
        (x0, y0, _), (x1, y1, _) = fence.min_enu_m, fence.max_enu_m
        ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ec="C3", lw=1.5, ls="-",
                               label=f"geofence {x1 - x0:g} x {y1 - y0:g} m"))  # fmt: skip
    elif fence is not None and fence.center_enu_m is not None and fence.radius_m is not None:
        ax.add_patch(Circle(fence.center_enu_m, fence.radius_m, fill=False, ec="C3", lw=1.5, label=f"geofence r = {fence.radius_m:g} m"))
    if reference is not None:
        ax.plot(reference[:, 0], reference[:, 1], color="k", ls="--", lw=1.3, label="path to follow")
    if waypoints is not None:
        ax.plot(waypoints[:, 0], waypoints[:, 1], "s", color="k", ms=4, label="way-points")
        for i, w in enumerate(waypoints):
            ax.annotate(str(i + 1), (w[0], w[1]), textcoords="offset points", xytext=(4, 4), fontsize=7)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, run in enumerate(runs):
        c = colors[k % len(colors)]
        p = run.col("position_enu_m")
        ax.plot(p[:, 0], p[:, 1], color=c, lw=1.1, label=run.name)
        ax.plot(p[0, 0], p[0, 1], "o", color=c, ms=5)
        if run.first_active > 0:
            ax.plot(p[run.first_active, 0], p[run.first_active, 1], "x", color=c, ms=7)
    ax.plot(0.0, 0.0, "+", color="0.3", ms=10, mew=1.5, label="origin (0, 0)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east, x (m)")
    ax.set_ylabel("north, y (m)")
    ax.set_title("Top view (o start, x path following begins)" + note, fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(out, dpi=_DPI)
    plt.close(fig)
    return out


def _focus_on_active(ax: object, run: Run, y: NDArray[np.float64], ref: NDArray[np.float64] | None = None) -> None:
    """Scale the y axis to the data from activation on.

    Before activation (a ballistic throw) the vehicle may pass far outside the tube |kappa xi1| < 1,
    where the exact transverse coordinates grow without bound (eta2 = <t, v> / (1 - kappa xi1));
    those values are logged as they are, but they must not flatten the part a reader looks at.
    """
    if not run.activation_s:
        return
    keep = run.t_s >= run.activation_s[0]
    shown = y[keep] if ref is None else np.concatenate([y[keep], ref[keep]])
    shown = shown[np.isfinite(shown)]
    if shown.size == 0 or np.all(np.isfinite(y[~keep]) & (y[~keep] >= shown.min()) & (y[~keep] <= shown.max())):
        return
    lo, hi = float(shown.min()), float(shown.max())
    pad = 0.08 * (hi - lo) if hi > lo else 0.1
    ax.set_ylim(lo - pad, hi + pad)  # type: ignore[attr-defined]
    ax.text(0.01, 0.02, "before activation: clipped", transform=ax.transAxes, fontsize=7, color="0.4")  # type: ignore[attr-defined]


def plot_tangential(run: Run, out: Path) -> Path:
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(2, 1, sharex=True, figsize=(6.4, 4.6))
    a1.plot(run.t_s, _break_wraps(run.col("eta1_m")), lw=1.3, label=r"$\eta_1$")
    a1.set_ylabel("along the path, " + r"$\eta_1$" + " (m)")
    a2.plot(run.t_s, run.col("eta2_m_s"), lw=1.3, label=r"$\eta_2$")
    ref = run.col("speed_ref_m_s")
    a2.plot(run.t_s, ref, "--", color="C3", lw=1.2, label=r"$\eta_2^{ref}$ = " + f"{ref[run.first_active]:.2f} m/s")
    a2.set_ylabel("speed along the path,\n" + r"$\eta_2$" + " (m/s)")
    a2.set_xlabel("time (s)")
    _focus_on_active(a2, run, run.col("eta2_m_s"), ref)
    for ax in (a1, a2):
        _mark_activation(ax, run, label=True)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="best")
    a1.set_title(f"Progress and speed along the path, {run.name}", fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=_DPI)
    plt.close(fig)
    return out


def plot_transversal(run: Run, out: Path) -> Path:
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, sharex=True, figsize=(7.6, 4.8))
    panels = (
        ("xi1_m", "off the path, normal direction,\n" + r"$\xi_1$" + " (cm)", r"$\xi_1$", 100.0),
        ("phi1_m", "off the path, binormal direction,\n" + r"$\varphi_1$" + " (cm)", r"$\varphi_1$", 100.0),
        ("xi2_m_s", "speed off the path, normal,\n" + r"$\xi_2$" + " (cm/s)", r"$\xi_2$", 100.0),
        ("phi2_m_s", "speed off the path, binormal,\n" + r"$\varphi_2$" + " (cm/s)", r"$\varphi_2$", 100.0),
    )
    for ax, (name, label, symbol, scale) in zip(axes.flat, panels):
        ax.plot(run.t_s, scale * run.col(name), lw=1.2, label=symbol)
        ax.axhline(0.0, color="k", lw=0.6)
        _focus_on_active(ax, run, scale * run.col(name))
        _mark_activation(ax, run, label=True)
        ax.set_ylabel(label, fontsize=8)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="best")
    for ax in axes[1]:
        ax.set_xlabel("time (s)")
    fig.suptitle(f"Distance and speed off the path (transversal states), {run.name}", fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=_DPI)
    plt.close(fig)
    return out


def tracking_line(run: Run, settle_s: float = 8.0) -> str:
    """How well a run followed its path: cross-track and speed-error RMS of the steps from
    activation + ``settle_s`` to the end of that active stretch (for logs that carry no summary)."""
    active = np.array([r.active for r in run.records])
    if not active.any():
        return f"{run.name}: never armed in OFFBOARD / GUIDED"
    start = int(np.argmax(active))
    stop = start + int(np.argmin(active[start:])) if not active[start:].all() else len(active)
    t = run.t_s
    window = (t >= t[start] + settle_s) & (np.arange(len(t)) < stop)
    if window.sum() < 2:
        return f"{run.name}: {t[stop - 1] - t[start]:.1f} s following, shorter than activation + {settle_s:g} s"
    e = run.col("cross_track_m")[window]
    dv = (run.col("eta2_m_s") - run.col("speed_ref_m_s"))[window]
    return (f"{run.name}: from activation + {settle_s:g} s ({t[window][-1] - t[window][0]:.1f} s): cross-track RMS "
            f"{100 * np.sqrt(np.mean(e**2)):.1f} cm, max {100 * np.max(e):.1f} cm; speed error RMS "
            f"{100 * np.sqrt(np.mean(dv**2)):.1f} cm/s (speed along the path from the position's derivative)")  # fmt: skip


def make_figures(
    logs: Sequence[str | Path], out_dir: str | Path, config_path: str | Path | None = None, title: str | None = None,
    report: list[str] | None = None,
) -> list[Path]:
    """Write the figures for ``logs`` into ``out_dir``; returns the PNG paths. ``report``: gets one
    :func:`tracking_line` per run of a log without its own summary (ULogs, other senders' tlogs)."""
    import matplotlib

    matplotlib.use("Agg")
    if not logs:
        raise InputError("LOG", "give at least one log")
    cfg = Path(config_path) if config_path is not None else FlightLogPaths.beside(logs[0]).config_yaml
    if config_path is not None and not cfg.exists():
        raise InputError("--config", f"no such file: {cfg}")
    runs = []
    for p in logs:
        loaded = load_runs(p, cfg if cfg.exists() else None)
        if report is not None and _is_foreign(Path(p)):
            report.extend(tracking_line(r) for r in loaded)
        runs += loaded
    names = [r.name for r in runs]
    if len(set(names)) != len(names):  # two runs called "flight": number them
        runs = [Run(f"{r.name}{i + 1}", r.records, r.t_s, r.activation_s) for i, r in enumerate(runs)]
    reference = _reference_path(cfg if cfg.exists() else None)
    waypoints = _waypoints(cfg if cfg.exists() else None)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ref_speed = runs[0].records[runs[0].first_active].speed_ref_m_s
    default_title = "Path following, " + r"$\eta_2^{ref}$" + (f" = {ref_speed:.2f} m/s" if math.isfinite(ref_speed) else "")
    pngs = [plot_path3d(runs, reference, out / "path3d.png", title or default_title, waypoints)]
    fence = fence_from_config(cfg if cfg.exists() else None)
    pngs.append(plot_map(runs, reference, fence, out / "map.png", _origin_note(Path(logs[0]).parent), waypoints))
    for run in runs:
        pngs.append(plot_tangential(run, out / f"{run.name}_tangential.png"))
        pngs.append(plot_transversal(run, out / f"{run.name}_transversal.png"))
    return pngs


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("logs", nargs="+", metavar="LOG",
                        help="pf-offboard step-log CSVs or .tlog files (with their sibling .csv); a PX4 ULog (.ulg) or a ground "
                             "station's .tlog with --config")  # fmt: skip
    parser.add_argument("--out", required=True, help="directory for the PNGs")
    parser.add_argument("--config", help="config file or shipped name for the path (default: the .yaml beside the first log)")
    parser.add_argument("--title", help="title of the 3-D path figure")


def run(args: argparse.Namespace) -> int:
    for p in args.logs:
        if not Path(p).exists():
            raise InputError(str(p), "no such file")
        if Path(p).is_dir():
            raise InputError("LOG", f"{p} is a directory; give its .csv or .tlog (e.g. {Path(p) / 'flight.csv'})")
    if args.config:
        from pf_offboard.shipped import resolve_config

        args.config = str(resolve_config(args.config))  # a file, or a shipped config's name
    make_dir(args.out, "--out")
    report: list[str] = []
    for png in make_figures(args.logs, args.out, args.config, args.title, report):
        print(png)
    for line in report:
        print(line)
    return 0
