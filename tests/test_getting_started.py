"""docs/getting-started.md is run as written: every command in its ```bash blocks, in order, in an
empty directory, against sitl-mock over loopback (the fixed ports of the page: run the suite in
its own network namespace; the test skips when the ports are taken).

- `# file: NAME` as the first line of a ```yaml block writes that block to NAME first;
- a command whose comment says "not run in the tests" needs hardware or a real SITL build;
- a `sitl-mock` line is "terminal 1": started in the background and stopped before the next one
  starts, with one change so the suite stays quick: the PX4 profile in lockstep (`--lockstep
  --lockstep-dt 0.02`, one step per setpoint of the configs' 50 Hz, as `pf-offboard demo` runs
  it: as fast as the host allows, and a loaded host cannot starve the flight); the ArduPilot
  profile at `--speed 4` (it takes off on its own while the app sends nothing, which a lockstep
  clock cannot advance);
- each command must exit 0; a flight's summary.json must report a cross-track RMS ≤ 5 cm.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pf_offboard.cli import main

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "getting-started.md"
NOT_RUN = "not run in the tests"
PLAN = ROOT / "tests" / "data" / "geo" / "mission.plan"  # the page's field.plan

pytestmark = pytest.mark.integration


def steps(text: str) -> list[tuple[str, str]]:
    """("file", "NAME\\nbody") and ("run", "command") in page order."""
    out: list[tuple[str, str]] = []
    for lang, body in re.findall(r"^ *```(bash|yaml)\n(.*?)^ *```", text, flags=re.S | re.M):
        lines = [line.strip() for line in body.splitlines()]
        if lang == "yaml":
            if lines and lines[0].startswith("# file: "):
                out.append(("file", lines[0].removeprefix("# file: ") + "\n" + body.split("\n", 1)[1]))
            continue
        out += [("run", line) for line in lines if line and not line.startswith("#")]
    return out


def _free(port: int, kind: int) -> bool:
    with socket.socket(socket.AF_INET, kind) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def _wait_for_mock(mock: subprocess.Popen) -> None:
    """Until the mock holds its ports: it prints them (``--print-ports``, one JSON line on stdout)
    once bound. An event, not a poll; a mock that exits first closes stdout (an empty line)."""
    assert mock.stdout is not None
    line = mock.stdout.readline()
    assert line, f"sitl-mock exited with {mock.wait(10)} before opening its ports"
    ports = json.loads(line)
    assert ports.get("udp") == 14580 or ports.get("tcp") == 5760, ports  # the page's ports


def _summaries(cwd: Path, before: set[Path]) -> list[Path]:
    return sorted(set(cwd.rglob("summary.json")) - before)


def test_page_parses_into_commands() -> None:
    cmds = [c for kind, c in steps(PAGE.read_text()) if kind == "run"]
    assert any(c.startswith("pf-offboard init myfield") for c in cmds)
    assert any(c.startswith("sitl-mock") for c in cmds) and any(c.startswith("pf-offboard fly") for c in cmds)
    not_run = [c for c in cmds if NOT_RUN in c]
    assert not_run and all(f"{NOT_RUN}: " in c for c in not_run)  # each says why


def test_every_command_of_the_guide_runs(tmp_path, monkeypatch, capsys) -> None:
    if not (_free(14540, socket.SOCK_DGRAM) and _free(14580, socket.SOCK_DGRAM) and _free(5760, socket.SOCK_STREAM)):
        pytest.skip("ports 14540 / 14580 / 5760 are in use: run the suite in its own network namespace")
    bin_dir = Path(sys.executable).parent
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ.get('PATH', '')}", "MPLBACKEND": "Agg"}
    shutil.copy(PLAN, tmp_path / "field.plan")
    mock: subprocess.Popen[str] | None = None
    ran: list[str] = []
    try:
        for kind, item in steps(PAGE.read_text()):
            if kind == "file":
                name, body = item.split("\n", 1)
                (tmp_path / name).write_text(body)
                continue
            if NOT_RUN in item:
                continue
            argv = shlex.split(item, comments=True)
            if argv[0] == "sitl-mock":
                if mock is not None:
                    mock.terminate()
                    mock.wait(10)
                    if mock.stdout is not None:
                        mock.stdout.close()
                clock = ["--speed", "4"] if "ardupilot" in argv else ["--lockstep", "--lockstep-dt", "0.02"]
                mock = subprocess.Popen([str(bin_dir / "sitl-mock"), *argv[1:], *clock, "--print-ports"], cwd=tmp_path, env=env,
                                        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)  # fmt: skip
                _wait_for_mock(mock)
                continue
            before = set(tmp_path.rglob("summary.json"))
            started = time.monotonic()
            assert argv[0] == "pf-offboard", item
            monkeypatch.chdir(tmp_path)
            code = main(argv[1:])  # the console script's entry point, in process (no interpreter start-up per command)
            out = capsys.readouterr()
            ran.append(item)
            with capsys.disabled():
                print(f"{time.monotonic() - started:5.1f} s  {item}")
            assert code == 0, f"{item}\n{out.out[-1500:]}\n{out.err[-2500:]}"
            for path in _summaries(tmp_path, before):
                summary = json.loads(path.read_text()).get("summary", {})
                # the window the docs quote: from activation + 8 s (the whole flight when shorter)
                window = summary.get("from_activation_plus_8s") or summary.get("whole_flight") or {}
                rms = window.get("cross_track_rms_m")
                with capsys.disabled():
                    print(f"       cross-track RMS {rms} m (at most 0.05 m)")
                assert rms is not None and rms <= 0.05, f"{item}: {path}: cross-track RMS {rms}"
    finally:
        if mock is not None:
            mock.terminate()
            mock.wait(10)
            if mock.stdout is not None:
                mock.stdout.close()
    assert any(c.startswith("pf-offboard fly") for c in ran)
