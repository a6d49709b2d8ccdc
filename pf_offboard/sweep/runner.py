"""One sweep flight as a self-contained task, and the executors that run many of them.

A :class:`FlightTask` carries everything a flight needs (the config's YAML text, not a path, and
the drawn start), so any process on any machine with ``pf_offboard`` installed runs it to the same
row: :func:`run_flight` is a pure function of its task. The executors only differ in where the
tasks run; rows come back sorted by (gain candidate, flight), so the table is identical for the
same seed whatever the executor:

- ``workers == 1`` and no cluster: in this process, one after the other;
- ``workers > 1``: a :class:`concurrent.futures.ProcessPoolExecutor` on this machine's cores;
- ``cluster``: a Dask cluster (:mod:`pf_offboard.sweep.engine`), the optional ``cluster`` extra.
"""

from __future__ import annotations

import math
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from pf_offboard.errors import InputError
from pf_offboard.sweep.gains import GainCandidate
from pf_offboard.sweep.rows import finish_row, outcome
from pf_offboard.sweep.starts import Start

# Fixed so a kept .tlog is the same file whoever runs the flight (and nothing reads the wall clock).
EPOCH_UNIX_S = 1.7e9
MAX_WORKERS = 256


@dataclass(frozen=True)
class FlightSettings:
    """How each sweep flight is flown and judged.

    Caught (the sweep's own criterion, not the flight summary's convergence): at the first active
    step with cross-track <= ``tube_m`` (and, when given,
    ``|eta2 - eta2_ref| <= speed_tol_m_s``) after which the cross-track never again exceeds
    ``stay_m`` (a tube with hysteresis); the catch time counts from activation (the first
    setpoint). A flight succeeds when it was caught at least ``settle_s`` before the end and never
    touched the ground. Two tubes, not one: a realistic vehicle's estimate is noisy (px4-sih:
    cross-track p99 ≈ 0.55 m in steady flight), so the last entry into one tight tube would
    measure the noise, and one wide tube alone would call a fast start that merely passes the
    path caught.
    """

    vehicle: str = "px4-sih"
    autopilot: str = "px4"
    output_mode: str | None = None  # default: the config's
    duration_s: float = 15.0
    rate_hz: float | None = None  # default: the config's
    tube_m: float = 0.3
    stay_m: float = 1.0
    speed_tol_m_s: float | None = None  # None: the speed error is not judged
    settle_s: float = 3.0

    def validate(self) -> FlightSettings:
        """Self, or an InputError naming the sweep flag that is out of range."""
        if not (math.isfinite(self.duration_s) and 1.0 <= self.duration_s <= 600.0):
            raise InputError("--duration", f"must be in [1, 600] s, got {self.duration_s}")
        if not (math.isfinite(self.tube_m) and 0.01 <= self.tube_m <= 20.0):
            raise InputError("--tube", f"must be in [0.01, 20] m, got {self.tube_m}")
        if not (math.isfinite(self.stay_m) and self.tube_m <= self.stay_m <= 50.0):
            raise InputError("--stay", f"must be in [--tube, 50] m, got {self.stay_m}")
        if self.speed_tol_m_s is not None and not (math.isfinite(self.speed_tol_m_s) and 0.01 <= self.speed_tol_m_s <= 20.0):
            raise InputError("--speed-tol", f"must be in [0.01, 20] m/s, got {self.speed_tol_m_s}")
        if not (math.isfinite(self.settle_s) and 0.0 <= self.settle_s < self.duration_s):
            raise InputError("--settle", f"must be in [0, --duration) s, got {self.settle_s}")
        return self


@dataclass(frozen=True)
class FlightTask:
    """One flight of a sweep: picklable, self-contained (see the module docstring)."""

    start: Start
    config_yaml: str  # the config's text (local way-points; gains already set for a candidate)
    settings: FlightSettings
    gains: GainCandidate | None = None
    logs_dir: str | None = None  # write this flight's logs to <logs_dir>/flight-<index> (on the worker)
    vehicle_index: int | None = None  # a sweep over several vehicles: this one's place (and a vehicle column)

    @property
    def key(self) -> tuple[int, ...]:
        key = (self.gains.id if self.gains is not None else -1, self.start.index)
        return key if self.vehicle_index is None else (self.vehicle_index, *key)

    def first_columns(self) -> dict[str, Any]:
        """The row's leading columns: the vehicle (several vehicles), the gain candidate, the start."""
        row: dict[str, Any] = {"vehicle": self.settings.vehicle} if self.vehicle_index is not None else {}
        if self.gains is not None:
            row.update(self.gains.columns())
        row.update(self.start.columns())
        return row


class _Judge:
    """Streams a flight's steps into its summary and judges the approach (see FlightSettings)."""

    def __init__(self, summary: Any, settings: FlightSettings) -> None:
        self.summary = summary
        self.tube_m = settings.tube_m
        self.speed_tol_m_s = settings.speed_tol_m_s if settings.speed_tol_m_s is not None else math.inf
        self.stay_m = settings.stay_m
        self.activation_s: float | None = None
        self.converged_s: float | None = None
        self.last_out_s: float | None = None  # the last active step beyond stay_m
        self.first_converged_s: float | None = None  # the first convergence, even if it did not hold
        self.max_out_m = 0.0  # the largest cross-track beyond stay_m after the first convergence
        self.max_after_m = 0.0  # cross-track maximum from convergence on
        self._sum2 = 0.0
        self._n = 0

    @property
    def rms_after_m(self) -> float:
        """Cross-track RMS from convergence on (NaN before)."""
        return math.sqrt(self._sum2 / self._n) if self._n else math.nan

    def add(self, record: Any) -> None:
        self.summary.add(record)
        if not record.active:
            return
        if self.activation_s is None:
            self.activation_s = record.time_s
        ct = record.cross_track_m
        if not ct <= self.stay_m:  # also NaN: out, start again
            self.last_out_s = record.time_s
            if self.first_converged_s is not None:
                self.max_out_m = max(self.max_out_m, ct) if math.isfinite(ct) else math.inf
            self.converged_s, self.max_after_m, self._sum2, self._n = None, 0.0, 0.0, 0
            return
        if self.converged_s is None:
            if not (ct <= self.tube_m and abs(record.eta2_m_s - record.speed_ref_m_s) <= self.speed_tol_m_s):
                return
            self.converged_s = record.time_s
            if self.first_converged_s is None:
                self.first_converged_s = record.time_s
        self.max_after_m = max(self.max_after_m, ct)
        self._sum2 += ct * ct
        self._n += 1

    def result(self) -> Any:
        return self.summary.result()


def sim_spec(task: FlightTask) -> Any:
    """The :class:`pf_offboard.sim.SimSpec` a task flies."""
    from pf_offboard.sim.flight import SimSpec

    st, s = task.start, task.settings
    name = f"flight-{st.index:06d}" + (f"-gains-{task.gains.id:03d}" if task.gains is not None else "")
    return SimSpec(
        throw_enu=st.position_enu_m + st.velocity_enu_m_s,
        throw_q_enu_flu=st.q_enu_flu,
        throw_body_rates_flu_rad_s=st.body_rates_flu_rad_s,
        throw_engage_after_s=0.0,  # the drawn state is the state at activation
        autopilot=s.autopilot,
        vehicle=s.vehicle,
        wind_enu_m_s=st.wind_enu_m_s,
        output_mode=s.output_mode,
        rate_hz=s.rate_hz,
        duration_s=s.duration_s,
        seed=st.sim_seed,
        epoch_unix_s=EPOCH_UNIX_S,
        name=name,
    )


def run_flight(task: FlightTask, observe: Callable[[Any], None] | None = None) -> dict[str, Any]:
    """Fly one task in process (no logs unless ``task.logs_dir``) and return its table row.
    ``observe``: called with the :class:`~pf_offboard.sim.flight.SimFlight` before it flies (to
    record more of it than the row; the tests compare the engines' trajectories this way)."""
    from pf_offboard.sim.flight import SimFlight

    st, s = task.start, task.settings
    spec = sim_spec(task)
    name = spec.name
    row = task.first_columns()
    with tempfile.TemporaryDirectory(prefix="pf-sweep-") as tmp:
        config_path = Path(tmp) / "config.yaml"
        config_path.write_text(task.config_yaml, encoding="utf-8")
        out_dir = Path(task.logs_dir) / name if task.logs_dir is not None else Path(tmp)
        try:
            flight = SimFlight(config_path, spec, out_dir, write_logs=task.logs_dir is not None)
            judge = _Judge(flight.summary, s)
            flight.summary = judge  # type: ignore[assignment]
            if observe is not None:
                observe(flight)
            result = flight.run()
        except Exception as exc:  # one broken flight is a row, not a lost sweep
            row.update(outcome(False, False, False, f"error: {type(exc).__name__}: {exc}", None, None, math.nan, math.nan, math.nan,
                                math.nan))  # fmt: skip
            row["first_in_tube_time_s"] = math.nan
            return row
    summ = result.summary
    judge_numbers = (judge.activation_s, judge.converged_s, judge.first_converged_s, judge.last_out_s, judge.max_out_m,
                     judge.max_after_m, judge.rms_after_m)  # fmt: skip
    return finish_row(row, s, result.reason, bool(result.crashed), result.sim_time_s, summ.whole_cross_track_max_m, *judge_numbers)


# ---------------------------------------------------------------------------------- progress
class Progress:
    """A plain-text progress bar on ``stream`` (stderr): redrawn in place on a terminal, one line
    per 10 % otherwise (logs, CI)."""

    WIDTH = 30

    def __init__(self, total: int, label: str = "sweep", stream: TextIO | None = None, clock: Callable[[], float] = time.monotonic) -> None:
        self.total = max(total, 1)
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.clock = clock
        self.t0 = clock()
        self.done = 0
        self.ok = 0
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._last_decile = -1

    def __call__(self, row: dict[str, Any]) -> None:
        self.update(bool(row["success"]))

    def update(self, success: bool) -> None:
        self.done += 1
        self.ok += int(bool(success))
        decile = 10 * self.done // self.total
        if self._tty or decile != self._last_decile or self.done == self.total:
            self._last_decile = decile
            end = "\n" if (not self._tty or self.done == self.total) else ""
            self.stream.write(("\r" if self._tty else "") + self.line() + end)
            self.stream.flush()

    def line(self) -> str:
        elapsed = max(self.clock() - self.t0, 1e-9)
        rate = self.done / elapsed
        left = (self.total - self.done) / rate if rate > 0 else math.inf
        filled = self.WIDTH * self.done // self.total
        eta = f"{int(left // 60)}:{int(left % 60):02d}" if math.isfinite(left) else "?"
        return (f"{self.label} [{'#' * filled}{'.' * (self.WIDTH - filled)}] {self.done}/{self.total} "
                f"ok {100.0 * self.ok / max(self.done, 1):.1f} % {rate:.2f} flights/s ETA {eta}")  # fmt: skip


# ---------------------------------------------------------------------------------- executors
def check_workers(workers: int) -> int:
    if not 1 <= workers <= MAX_WORKERS:
        raise InputError("--workers", f"must be in [1, {MAX_WORKERS}], got {workers}")
    return workers


ENGINES = ("batch", "scalar")


def execute(tasks: Sequence[FlightTask], workers: int = 1, cluster: str | None = None,
            on_row: Callable[[dict[str, Any]], None] | None = None, client: Any = None,
            engine: str = "batch") -> list[dict[str, Any]]:  # fmt: skip
    """Every task's row, sorted by (gain candidate, flight), whatever ran them (module docstring).

    ``on_row``: called with each row as it comes back (a :class:`Progress`, a journal);
    ``client``: an existing ``distributed.Client`` (tests, notebooks) instead of ``cluster``;
    ``engine``: ``batch`` flies the flights it mirrors as arrays, many per process
    (:mod:`pf_offboard.sim.batch.flight`), and the rest one by one like ``scalar``: the same rows."""
    check_workers(workers)
    if engine not in ENGINES:
        raise InputError("--engine", f"must be one of {', '.join(ENGINES)}, got {engine!r}")
    if engine == "batch":
        return _collect(_batched(tasks, workers, cluster, client), len(tasks), on_row)
    return _collect(_scalar(tasks, workers, cluster, client), len(tasks), on_row)


def _scalar(tasks: Sequence[FlightTask], workers: int, cluster: str | None, client: Any) -> Iterable[tuple[tuple[int, int], dict[str, Any]]]:
    if not tasks:
        return iter(())
    if cluster is not None or client is not None:
        from pf_offboard.sweep.engine import run_on_dask

        return run_on_dask(tasks, run_flight, cluster, workers, client=client)
    if workers == 1:
        return ((t.key, run_flight(t)) for t in tasks)
    return _pool(tasks, workers)


def _batched(tasks: Sequence[FlightTask], workers: int, cluster: str | None, client: Any) -> Iterable[tuple[tuple[int, int], dict[str, Any]]]:
    """Chunks of the batch engine, then the scalar flights (unsupported, or handed back)."""
    from pf_offboard.sim.batch.flight import plan_chunks, run_chunk

    dask = cluster is not None or client is not None
    chunks, scalar = plan_chunks(tasks, workers if not dask else max(workers, 2))
    if dask:
        from pf_offboard.sweep.engine import run_on_dask

        done = run_on_dask(chunks, run_chunk, cluster, workers, client=client)
    elif workers == 1 or len(chunks) <= 1:
        done = ((c.key, run_chunk(c)) for c in chunks)
    else:
        done = _pool(chunks, workers, run_chunk)  # type: ignore[arg-type]
    for _, result in done:
        yield from result["rows"]
        scalar.extend(result["redo"])
    yield from _scalar(scalar, workers, cluster, client)


def rows_equal(a: Sequence[dict[str, Any]], b: Sequence[dict[str, Any]]) -> bool:
    """Tables equal value for value, NaN equal to NaN (``==`` says NaN != NaN once a row has
    crossed a process boundary: only the identical NaN object compares equal)."""

    def same(x: Any, y: Any) -> bool:
        return x == y or (isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y))

    return len(a) == len(b) and all(ra.keys() == rb.keys() and all(same(ra[k], rb[k]) for k in ra) for ra, rb in zip(a, b))


def _pool(tasks: Sequence[Any], workers: int, fn: Callable[[Any], Any] | None = None) -> Iterable[tuple[Any, Any]]:
    from concurrent.futures import ProcessPoolExecutor, as_completed

    with ProcessPoolExecutor(max_workers=min(workers, max(len(tasks), 1))) as pool:
        futures = {pool.submit(fn or run_flight, t): t.key for t in tasks}
        try:
            for fut in as_completed(futures):
                yield futures[fut], fut.result()
        finally:
            for fut in futures:
                fut.cancel()


def _collect(done: Iterable[tuple[tuple[int, ...], dict[str, Any]]], total: int,
             on_row: Callable[[dict[str, Any]], None] | None) -> list[dict[str, Any]]:  # fmt: skip
    rows: dict[tuple[int, ...], dict[str, Any]] = {}
    for key, row in done:
        rows[key] = row
        if on_row is not None:
            on_row(row)
    if len(rows) != total:
        raise RuntimeError(f"sweep: {total} flights submitted, {len(rows)} rows came back")
    return [rows[k] for k in sorted(rows)]
