"""``pf-offboard bench --only memory``: resident memory over a long flight (issue 9, item 7).

A figure, not a test: ``sim`` and ``fly`` (against ``sitl-mock`` in lockstep, over loopback UDP)
each fly the paper path for an hour of simulated time (``--quick``: 10 minutes, ``--minutes N``:
N) while the process's resident set size (RSS, /proc/self/statm) is sampled; for ``fly`` the
mock's process too (``mock_*``). Reported: RSS after 1 minute of simulated time, at the end, the
maximum after the first minute, and the growth in percent of the 1-minute value (the target:
within 20 %).

Why this exists: ``sim`` kept every step in memory (~1.5 KB each) and ``fly`` read its whole step
log back for the summary; an hour at 250 Hz would have needed GBs. Both now stream the steps to
the CSV and keep only running sums (:class:`pf_offboard.logs.summary.SummaryAccumulator`).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

WARMUP_S = 60.0  # simulated seconds before the reference sample


def rss_bytes(pid: int | str = "self") -> int:
    """Resident set size of this process, or of ``pid`` (Linux /proc; 0 where unavailable)."""
    try:
        with open(f"/proc/{pid}/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0


class _Samples:
    def __init__(self, name: str, pid: int | str = "self") -> None:
        self.name = name
        self.pid = pid
        self.at_warmup: int | None = None
        self.max_after: int = 0
        self.last_time_s = 0.0
        self._next_report_s = WARMUP_S

    def add(self, sim_time_s: float) -> None:
        self.last_time_s = sim_time_s
        if sim_time_s < WARMUP_S:
            return
        rss = rss_bytes(self.pid)
        if sim_time_s >= self._next_report_s:  # progress on stderr: a long run's figures so far
            print(f"[memory] {self.name}: {sim_time_s:7.0f} s simulated, RSS {rss / 2**20:.1f} MB", file=sys.stderr, flush=True)
            self._next_report_s += 300.0
        if self.at_warmup is None:
            self.at_warmup = rss
        self.max_after = max(self.max_after, rss)

    def figures(self, prefix: str, wall_s: float, end: int | None = None) -> dict[str, Any]:
        end = rss_bytes(self.pid) if end is None else end
        ref = self.at_warmup or end
        mb = 1024.0 * 1024.0
        return {
            f"{prefix}_simulated_s": round(self.last_time_s, 1),
            f"{prefix}_wall_s": round(wall_s, 1),
            f"{prefix}_rss_after_1min_MB": ref / mb,
            f"{prefix}_rss_end_MB": end / mb,
            f"{prefix}_rss_max_after_1min_MB": max(self.max_after, end) / mb,
            f"{prefix}_rss_growth_pct": 100.0 * (max(self.max_after, end) - ref) / ref if ref else float("nan"),
        }


def _config() -> Path:
    from pf_offboard.app.demo import paper_config

    return paper_config()


def bench_sim(duration_s: float, out_dir: Path) -> dict[str, Any]:
    from pf_offboard.sim import SimSpec
    from pf_offboard.sim.flight import SimFlight

    samples = _Samples("sim")
    flight = SimFlight(_config(), SimSpec(vehicle="fast", duration_s=duration_s, epoch_unix_s=1.7e9, name="memory"), out_dir)
    flight.progress = samples.add
    t0 = time.perf_counter()
    result = flight.run()
    samples.add(result.sim_time_s)
    return samples.figures("sim", time.perf_counter() - t0)


def bench_fly(duration_s: float, out_dir: Path) -> dict[str, Any]:
    from sitl_mock.config import MockConfig, SpawnSpec
    from sitl_mock.runner import spawn

    from pf_offboard.app.fly import add_arguments, fly
    from pf_offboard.config import load_config

    config_path = _config()
    rate_hz = load_config(config_path).flight.setpoint_rate_hz
    samples = _Samples("fly")
    mock_samples: list[_Samples] = []  # the mock's process, once spawned
    stop = threading.Event()
    bridges: list[Any] = []

    def sampler() -> None:  # the flight's own clock, read from another thread (a float attribute)
        while not stop.wait(0.5):
            if bridges and bridges[0].last_step is not None:
                t = bridges[0].last_step.record.time_s
                samples.add(t)
                for m in mock_samples:
                    m.add(t)

    mock_config = MockConfig(vehicle="fast", profile="px4", spawn=SpawnSpec.parse("hover:-3,0,-2"), udp_local_port=0, udp_remote=None,
                             lockstep=True, lockstep_dt_s=1.0 / rate_hz)  # fmt: skip
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    thread = threading.Thread(target=sampler, daemon=True)
    t0 = time.perf_counter()
    with spawn(mock_config) as mock:
        args = parser.parse_args(["--connect", f"udpout:127.0.0.1:{mock.ports.udp}", "--config", str(config_path), "--airborne",
                                  "--duration", str(duration_s), "--log-dir", str(out_dir), "--quiet", "--heartbeat-timeout", "10"])  # fmt: skip
        mock_samples.append(_Samples("mock", mock.process.pid))
        thread.start()
        with open(os.devnull, "w") as quiet:
            outcome = fly(args, status_stream=quiet, on_start=bridges.append)
        stop.set()
        thread.join(5.0)
        mock_end = rss_bytes(mock.process.pid)  # before the mock is stopped
    wall_s = time.perf_counter() - t0
    if outcome.summary is not None:
        samples.last_time_s = max(samples.last_time_s, (outcome.summary.duration_s or 0.0))
    figures = samples.figures("fly", wall_s)
    figures["fly_exit_code"] = outcome.exit_code
    if mock_end:  # Linux: the mock's process as well (its own logs must not grow either)
        figures.update({k: v for k, v in mock_samples[0].figures("mock", wall_s, mock_end).items() if "rss" in k})
    return figures


def run(quick: bool = False, only: str | None = None, minutes: float | None = None) -> dict[str, Any]:
    duration_s = 60.0 * minutes if minutes is not None else (600.0 if quick else 3600.0)
    which = (only,) if only else ("sim", "fly")
    out: dict[str, Any] = {"simulated_s_per_run": duration_s}
    with tempfile.TemporaryDirectory(prefix="pf-bench-memory-") as tmp:
        if "sim" in which:
            out.update(bench_sim(duration_s, Path(tmp) / "sim"))
        if "fly" in which:
            out.update(bench_fly(duration_s, Path(tmp) / "fly"))
    return out


if __name__ == "__main__":  # python -m pf_offboard.bench.memory [sim|fly] [--quick] [--minutes N]
    import json

    argv = sys.argv[1:]
    mins = float(argv[argv.index("--minutes") + 1]) if "--minutes" in argv else None
    print(json.dumps(run(quick="--quick" in argv, only=next((a for a in argv if a in ("sim", "fly")), None), minutes=mins), indent=2))
