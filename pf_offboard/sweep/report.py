"""What a sweep leaves behind: the table, its statistics, and the region-of-attraction plot.

- ``flights.partial.csv``: the rows as they come back, while the sweep runs;
- ``flights.csv``: one row per flight (start, outcome; units in the column names), always;
  ``flights.parquet`` too when ``pyarrow`` is installed (it is not a dependency);
- ``summary.json``: success rate, catch-time percentiles over the successful flights, the
  failures by kind with the ranges of their starts, the settings and the wall time;
- ``roa.png``: initial distance from the path against initial speed, each flight coloured by its
  time to be caught, failures marked (plus that time against distance).
"""

from __future__ import annotations

import csv
import math
from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

PERCENTILES = (50, 90, 95, 99)
MAX_LISTED = 200  # failed flights listed one by one in summary.json (all are in the table)
START_COLUMNS = ("distance_m", "speed_m_s", "tilt_deg", "rate_rad_s", "wind_m_s", "pos_enu_z_m", "vel_enu_z_m_s")


JOURNAL_CSV = "flights.partial.csv"


class Journal:
    """Appends each row to a CSV as it comes back (completion order, flushed): a long sweep that
    is stopped keeps what it flew. The sorted ``flights.csv`` replaces it at the end."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._fh = open(path, "w", newline="", encoding="utf-8")
        self._writer: csv.DictWriter[str] | None = None

    def __enter__(self) -> Journal:
        return self

    def __exit__(self, *exc: object) -> None:
        self._fh.close()

    def __call__(self, row: Mapping[str, Any]) -> None:
        if self._writer is None:
            self._writer = csv.DictWriter(self._fh, fieldnames=list(row), lineterminator="\n")
            self._writer.writeheader()
        self._writer.writerow(row)
        self._fh.flush()


def write_table(rows: Sequence[Mapping[str, Any]], out_dir: Path, stem: str = "flights") -> list[Path]:
    """``<stem>.csv`` (floats in shortest round-trip form) and, with pyarrow, ``<stem>.parquet``."""
    written = [out_dir / f"{stem}.csv"]
    columns = list(rows[0]) if rows else []
    with open(written[0], "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=columns, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return written
    written.append(out_dir / f"{stem}.parquet")
    pq.write_table(pa.Table.from_pylist([dict(r) for r in rows]), written[1])
    return written


def convergence_percentiles(rows: Sequence[Mapping[str, Any]], column: str = "caught_time_s") -> dict[str, float]:
    """Percentiles, mean and max of a time column (s) over the successful flights."""
    times = np.array([r[column] for r in rows if r["success"]], dtype=float)
    if times.size == 0:
        return {**{f"p{q}_s": math.nan for q in PERCENTILES}, "mean_s": math.nan, "max_s": math.nan}
    out = {f"p{q}_s": float(np.percentile(times, q)) for q in PERCENTILES}
    out.update(mean_s=float(times.mean()), max_s=float(times.max()))
    return out


def failure_kind(row: Mapping[str, Any]) -> str:
    reason = str(row["reason"])
    if reason.startswith("error"):
        return "error"
    if row["crashed"]:
        return "crashed"
    if row["ground_contact"]:
        return "touched the ground"
    if "caught only" in reason:
        return "caught too late"
    return "left the tube after being caught" if "and not back" in reason else "never caught"


def success_by_bin(rows: Sequence[Mapping[str, Any]], bins: int = 4) -> dict[str, list[dict[str, float]]]:
    """Per start quantity: the success rate in ``bins`` equal-width bins of its range."""
    out: dict[str, list[dict[str, float]]] = {}
    for col in START_COLUMNS:
        values = np.array([r[col] for r in rows], dtype=float)
        ok = np.array([bool(r["success"]) for r in rows])
        if values.size == 0:
            continue
        edges = np.linspace(values.min(), values.max(), bins + 1)
        which = np.clip(np.searchsorted(edges, values, side="right") - 1, 0, bins - 1)
        out[col] = [{"from": float(edges[b]), "to": float(edges[b + 1]), "flights": int((which == b).sum()),
                     "success_rate": float(ok[which == b].mean()) if (which == b).any() else math.nan}
                    for b in range(bins)]  # fmt: skip
    return out


def _ranges(rows: Sequence[Mapping[str, Any]]) -> dict[str, list[float]]:
    return {c: [float(min(r[c] for r in rows)), float(max(r[c] for r in rows))] for c in START_COLUMNS} if rows else {}


def sim_command(row: Mapping[str, Any], config: str, flight: Mapping[str, Any]) -> str:
    """The ``pf-offboard sim`` command that flies this row's flight again, with its logs
    (``flight``: the sweep's :class:`~pf_offboard.sweep.runner.FlightSettings` as a dict; a gain
    sweep's row needs the candidate's config, ``best-gains.yaml`` style, in ``config``)."""

    def vec(fmt: str, axes: str) -> str:
        return ",".join(repr(float(row[fmt.format(a)])) for a in axes)

    from pf_offboard.sweep.runner import EPOCH_UNIX_S

    args = [
        "pf-offboard sim", f"--config {config}", f"--vehicle {row.get('vehicle', flight['vehicle'])}", f"--autopilot {flight['autopilot']}",
        f"--throw={vec('pos_enu_{}_m', 'xyz')},{vec('vel_enu_{}_m_s', 'xyz')}", f"--throw-attitude={vec('q_enu_flu_{}', 'wxyz')}",
        f"--throw-rates={vec('rate_flu_{}_rad_s', 'xyz')}", "--throw-engage-after 0", f"--wind={vec('wind_enu_{}_m_s', 'xyz')}",
        f"--seed {row['sim_seed']}", f"--duration {flight['duration_s']!r}", f"--epoch {EPOCH_UNIX_S!r}",
    ]  # fmt: skip
    args += [f"--output {flight['output_mode']}"] if flight.get("output_mode") else []
    args += [f"--rate {flight['rate_hz']!r}"] if flight.get("rate_hz") else []
    return " ".join(args + [f"--out flight-{row['flight']:06d}"])


def summarize(rows: Sequence[Mapping[str, Any]], config: str = "CONFIG", flight: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Success rate, catch-time statistics and the failures (kinds, start ranges, flights;
    with ``flight`` settings, each failure's ``sim`` command)."""
    n = len(rows)
    failed = [r for r in rows if not r["success"]]
    return {
        "flights": n,
        "successes": n - len(failed),
        "success_rate": (n - len(failed)) / n if n else math.nan,
        "caught_time": convergence_percentiles(rows),
        # the first step within the inner tube, even if a later excursion beyond the outer one reset
        # being caught: the approach alone
        "first_in_tube_time": convergence_percentiles(rows, "first_in_tube_time_s"),
        "failures_by_kind": dict(sorted(Counter(failure_kind(r) for r in failed).items())),
        "failed_start_ranges": _ranges(failed),
        "success_rate_by_start": success_by_bin(rows),
        "all_start_ranges": _ranges(rows),
        "failed_flights": [{"flight": r["flight"], **({"gains_id": r["gains_id"]} if "gains_id" in r else {}),
                            "reason": r["reason"], **{c: r[c] for c in START_COLUMNS},
                            **({"sim": sim_command(r, config, flight)} if flight is not None else {})}
                           for r in failed[:MAX_LISTED]],  # fmt: skip
    }


def lines(stats: Mapping[str, Any]) -> list[str]:
    """The summary for a terminal."""
    c, a = stats["caught_time"], stats["first_in_tube_time"]
    out = [
        f"flights             {stats['flights']}, caught {stats['successes']} "
        f"({100.0 * stats['success_rate']:.1f} %)",
        "caught after       " + ", ".join(f"p{q} {c[f'p{q}_s']:.2f} s" for q in PERCENTILES) + f", max {c['max_s']:.2f} s"
        " (after activation, successful flights)",
        "first in the tube   " + ", ".join(f"p{q} {a[f'p{q}_s']:.2f} s" for q in PERCENTILES) + f", max {a['max_s']:.2f} s",
    ]
    if stats["failures_by_kind"]:
        out.append("failures            " + ", ".join(f"{k}: {v}" for k, v in stats["failures_by_kind"].items()))
        for col, (lo, hi) in stats["failed_start_ranges"].items():
            alo, ahi = stats["all_start_ranges"][col]
            by = " ".join(f"{100 * b['success_rate']:.0f}%" for b in stats["success_rate_by_start"][col])
            out.append(f"  failed starts     {col:<14} {lo:8.2f} .. {hi:8.2f}   (all starts {alo:.2f} .. {ahi:.2f}; "
                       f"success by quarter of that range: {by})")  # fmt: skip
    return out


def write_json(data: Mapping[str, Any], path: Path) -> None:
    """Strict JSON (NaN / inf as null), like the flight report."""
    from pf_offboard.logs.summary import report_json

    path.write_text(report_json(dict(data)) + "\n", encoding="utf-8")


def roa_plot(rows: Sequence[Mapping[str, Any]], path: Path, title: str, dpi: int = 110) -> Path:
    """Region of attraction: initial distance vs speed coloured by the time to be caught (failures: red
    crosses), and that time vs initial distance. PNG, matplotlib's Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = [r for r in rows if r["success"]]
    bad = [r for r in rows if not r["success"]]
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 5), constrained_layout=True)
    if ok:
        sc = ax.scatter([r["distance_m"] for r in ok], [r["speed_m_s"] for r in ok], c=[r["caught_time_s"] for r in ok],
                        s=14, cmap="viridis", label=f"caught ({len(ok)})")  # fmt: skip
        fig.colorbar(sc, ax=ax, label="time to be caught (s)")
        sc2 = ax2.scatter([r["distance_m"] for r in ok], [r["caught_time_s"] for r in ok], s=10,
                          c=[r["speed_m_s"] for r in ok], cmap="plasma")  # fmt: skip
        fig.colorbar(sc2, ax=ax2, label="initial speed (m/s)")
    if bad:
        ax.scatter([r["distance_m"] for r in bad], [r["speed_m_s"] for r in bad], marker="x", color="red", s=30,
                   label=f"failed ({len(bad)})")  # fmt: skip
    ax.set_xlabel("initial distance from the path (m)")
    ax.set_ylabel("initial speed (m/s)")
    ax.set_title(title)
    ax.legend(loc="upper right")
    ax2.set_xlabel("initial distance from the path (m)")
    ax2.set_ylabel("time to be caught (s)")
    ax2.set_title("time to be caught vs distance (caught flights)")
    for a in (ax, ax2):
        a.grid(True, alpha=0.3)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path
