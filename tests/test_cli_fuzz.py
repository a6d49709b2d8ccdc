"""CLI fuzzing: every command given at least one bad argument — long names, devices, FIFOs,
directories, huge or binary files, malformed numbers and endpoints — exits 2 with one line on
stderr: no traceback, no hang (an alarm per case), bounded memory (devices and oversized files
are never read), and nothing is opened towards a vehicle (``Link.open`` raises if reached)."""

from __future__ import annotations

import contextlib
import io
import os
import shutil
import signal
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pf_offboard import cli

REPO = Path(__file__).resolve().parents[1]
CASES = settings(max_examples=1100, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))


class _Hang(Exception):
    pass


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, str]:
    d = tmp_path_factory.mktemp("cli_fuzz")
    os.mkfifo(d / "fifo", 0o600)
    (d / "dir").mkdir()
    big = d / "huge.yaml"
    with open(big, "wb") as fh:  # sparse: 3 GiB that take no space, larger than any input's limit
        fh.truncate(3 << 30)
    (d / "junk.tlog").write_bytes(bytes(range(256)) * 8)
    (d / "latin1.yaml").write_bytes(b"path: caf\xe9\n")
    shutil.copy(REPO / "configs" / "paper.yaml", d / "good.yaml")
    (d / "key").write_text("a long enough passphrase\n")
    (d / "key").chmod(0o600)
    (d / "out").mkdir()
    return {k: str(d / v) for k, v in (("fifo", "fifo"), ("dir", "dir"), ("huge", "huge.yaml"), ("junk", "junk.tlog"),
                                       ("latin1", "latin1.yaml"), ("good", "good.yaml"), ("key", "key"), ("missing", "nope.yaml"),
                                       ("out", "out"))}  # fmt: skip


def bad_files(f: dict[str, str]) -> list[str]:
    return [f["fifo"], f["dir"], f["huge"], f["junk"], f["latin1"], f["missing"], "/dev/zero", "/dev/null", "x" * 300, "y" * 5000,
            "", f["dir"] + "/" + "z" * 255 + "/a", "\udcff\udcfe.yaml"]  # fmt: skip


def bad_outputs(f: dict[str, str]) -> list[str]:
    """Where nothing can be written: a name too long, a path under a regular file, an empty name, a
    directory where a file goes (and a file where a directory goes), an existing FIFO / device."""
    return ["y" * 5000, f["good"] + "/sub/x", "", f["dir"], f["good"], f["fifo"], "/dev/zero", f["dir"] + "/" + "z" * 300]


BAD_NUMBERS = ["nan", "inf", "-inf", "-1", "0", "1e400", "abc", "", "9" * 500, "-0", "1e-320", "0x10"]
BAD_ENDPOINTS = ["udpout:256.1.1.1:14540", "udpout:1.2.3:14540", "udpout:127.0.0.1:0", "udpout:127.0.0.1:99999", "tcp:-x:5760",
                 "serial:/dev/null:57600", "serial:/dev/zero:57600", "serial:/nonexistent:57600", "x" * 5000, "udpin:", ":::",
                 "tcp:a..b:5760", "udpin:0.0.0.0:14540:7"]  # fmt: skip


def _commands(f: dict[str, str]) -> dict[str, list[tuple[str | None, str, str]]]:
    """Per command: (flag or None for a positional, a good value, the kind of bad values)."""
    return {
        "fly": [("--connect", "udpout:127.0.0.1:14540", "endpoint"), ("--config", f["good"], "file"), ("--airborne", "", "flag"),
                ("--duration", "5", "number"), ("--heartbeat-timeout", "1", "number"), ("--ready-timeout", "5", "number"),
                ("--target-system", "1", "number"), ("--signing-key", f["key"], "file"), ("--log-dir", f["out"], "dir")],
        "sim": [("--config", f["good"], "file"), ("--out", f["out"], "dir"), ("--duration", "0.2", "number"),
                ("--rate", "100", "number"), ("--seed", "1", "seed"), ("--start", "0,-3,2", "number")],
        "replay": [(None, f["junk"], "file"), ("--config", f["good"], "file"), ("--steps", f["junk"], "file"),
                   ("--tolerance", "0.01", "number")],
        "identify": [(None, f["junk"], "file"), ("--hover-thrust", "0.5", "number"), ("--velocity-correction", "0.3", "number")],
        "plot": [(None, f["junk"], "file"), ("--out", f["out"], "dir"), ("--config", f["good"], "file")],
        # --out's good value exists (init refuses to overwrite it): a run never writes, so cases stay independent
        "init": [(None, "mine", "name"), ("--from", "paper", "file"), ("--out", f["good"], "output")],
    }  # fmt: skip


def _argv(draw, f: dict[str, str]) -> list[str]:
    command = draw(st.sampled_from(sorted(_commands(f))))
    slots = _commands(f)[command]
    bad_slots = draw(st.sets(st.integers(0, len(slots) - 1), min_size=1, max_size=3))
    pools = {"file": bad_files(f), "dir": [p for p in bad_outputs(f) if p != f["dir"]], "output": bad_outputs(f), "number": BAD_NUMBERS, "endpoint": BAD_ENDPOINTS, "name": ["mine"], "seed": ["abc", "nan", "1.5", "-1", "1e400", ""], "flag": ["--no-such-flag"]}  # fmt: skip
    if command == "identify" and all(flag is not None and kind == "number" for i, (flag, _, kind) in enumerate(slots) if i in bad_slots):
        bad_slots = bad_slots | {0}  # a good log would be fitted: keep the junk one (bad input as well)
    argv = [command]
    for i, (flag, good, kind) in enumerate(slots):
        value = draw(st.sampled_from(pools[kind])) if i in bad_slots else good
        if kind == "flag":
            argv.append(value or flag)
        elif flag is None:
            argv.append(value)
        else:
            argv += [flag, value] if not value.startswith("-") else [f"{flag}={value}"]
    return argv


@st.composite
def argvs(draw, f):
    return _argv(draw, f)


def test_cli_bad_input_is_one_line_exit_2(files, monkeypatch) -> None:
    from pf_offboard.app import link

    def no_connect(*_a, **_k):
        raise AssertionError(f"bad input reached Link.open (something would have been sent): {[a[:80] for a in seen[-1]]}")

    monkeypatch.setattr(link.Link, "open", classmethod(no_connect))
    monkeypatch.chdir(Path(files["out"]).parent)
    seen: list[list[str]] = []

    def alarm(_sig, _frame):
        raise _Hang()

    previous = signal.signal(signal.SIGALRM, alarm)
    try:

        @CASES
        @given(argv=argvs(files))
        def run(argv: list[str]) -> None:
            seen.append(argv)
            err, out = io.StringIO(), io.StringIO()
            signal.alarm(20)
            try:
                with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
                    try:
                        code = cli.main(argv)
                    except SystemExit as exc:  # argparse
                        code = exc.code if isinstance(exc.code, int) else 2
            except _Hang:
                pytest.fail(f"hung: {argv!r:.300}")
            finally:
                signal.alarm(0)
            lines = [line for line in err.getvalue().splitlines() if line.strip() and "warning:" not in line]
            assert code == 2, (" ".join(a[:80] for a in argv), code, err.getvalue()[-600:])
            assert len(lines) == 1 and "Traceback" not in err.getvalue(), (argv, err.getvalue()[-600:])

        run()
    finally:
        signal.signal(signal.SIGALRM, previous)
    assert len(seen) >= 1000
