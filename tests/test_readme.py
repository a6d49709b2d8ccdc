"""The README's two set-up commands stay true: CI runs exactly the README's test command."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _readme_commands() -> list[str]:
    text = (ROOT / "README.md").read_text()
    setup = text.split("## Set up", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"```bash\n(.+?)\n```", setup, flags=re.S)


def test_readme_has_exactly_two_setup_commands():
    cmds = _readme_commands()
    assert len(cmds) == 2, cmds
    assert "pf-offboard demo" in cmds[0]
    assert "pytest" in cmds[1]


def test_ci_runs_the_readme_test_command():
    ci = (ROOT / ".ci" / "run").read_text().splitlines()
    assert _readme_commands()[1] in ci


def test_readme_real_autopilot_table_is_generated_from_its_data(script):
    import json

    gen = script("gen_readme_table")

    data = json.loads((ROOT / "docs" / "data" / "real_sitl.json").read_text())
    assert gen.block((ROOT / "README.md").read_text()) == gen.render(data)
    assert gen.main(["--check"]) == 0


def test_readme_rows_come_from_a_campaigns_results(tmp_path, script):
    """``--from-campaign``: one row per autopilot and output at the config's speed, one per
    autopilot with the profile (mean speeds in its label); failed flights, starts and flights without a
    speed measured in the window left out."""
    import json

    gen = script("gen_readme_table")

    def flight(name, autopilot, output, vmax, rms, speed_err, mean, exit_code=0, **extra):
        d = tmp_path / name
        d.mkdir()
        settled = {"cross_track_rms_m": rms, "speed_error_rms_m_s": speed_err, "speed_mean_m_s": mean}
        spec = {"autopilot": autopilot, "output": output, "max_speed_m_s": vmax, **extra}
        (d / "result.json").write_text(json.dumps({"spec": spec, "exit_code": exit_code, "tracking": {"settled": settled}}))

    flight("a", "px4", "attitude", None, 0.031, 0.07, 1.5)
    flight("b", "px4", "attitude", None, 0.045, 0.09, 1.49)
    flight("c", "px4", "rates", None, 0.5, 0.9, 1.2, exit_code=5)  # did not complete
    flight("d", "px4", "rates", 3.0, 0.062, 0.15, 2.27)
    flight("e", "px4", "acceleration", 3.0, 0.05, 0.12, 2.81)
    flight("f", "arducopter", "rates", None, 0.01, 0.02, 1.5, throw=[1, 2])  # a start, not a row
    flight("g", "px4", "rates", 3.0, 0.015, None, None)  # no speed in the window: not a measure
    rows = gen.campaign_rows(tmp_path)
    assert rows == [
        {"autopilot": "PX4 SIH", "output": "attitude", "config": "default", "laps": 3, "flights": "2",
         "cross_track_rms_cm": [3.1, 4.5], "speed_error_rms_cm_s": [7.0, 9.0]},
        {"autopilot": "PX4 SIH, profile to 3 m/s (2.3–2.8 m/s mean)", "output": "acceleration / rates", "config": "default",
         "laps": 3, "flights": "2", "cross_track_rms_cm": [5.0, 6.2], "speed_error_rms_cm_s": [12.0, 15.0]},
    ]


def test_readme_is_short():
    assert len((ROOT / "README.md").read_bytes()) <= 10 * 1024


def test_readme_fly_example_runs_up_to_the_real_vehicle(tmp_path, monkeypatch) -> None:
    """The README's `Fly a real vehicle` block, run as written in an empty directory; the last
    command needs a vehicle on a serial port and is only parsed."""
    import shlex

    from pf_offboard.cli import build_parser, main

    text = (ROOT / "README.md").read_text()
    block = text.split("## Fly a real vehicle", 1)[1].split("\n## ", 1)[0]
    commands = [c for c in re.findall(r"```bash\n(.+?)\n```", block, flags=re.S)[0].splitlines() if c.strip()]
    monkeypatch.chdir(tmp_path)
    for line in commands:
        argv = shlex.split(line, comments=True)
        assert argv[0] == "pf-offboard"
        if any(a.startswith("serial:") for a in argv):
            build_parser().parse_args(argv[1:])  # a real vehicle: the command line at least parses
            continue
        assert main(argv[1:]) == 0, line


def test_readme_minimal_config_loads_and_flies_in_sim(tmp_path) -> None:
    """The README's `field.yaml` (a path and a speed only) is valid and follows its path."""
    import yaml

    from pf_offboard.cli import main
    from pf_offboard.config import parse_config

    text = (ROOT / "README.md").read_text()
    block = re.findall(r"```yaml\n(.+?)\n```", text, flags=re.S)[0]
    parse_config(yaml.safe_load(block))
    (tmp_path / "field.yaml").write_text(block)
    assert main(["sim", "--config", str(tmp_path / "field.yaml"), "--laps", "2", "--out", str(tmp_path / "run"), "--json"]) == 0
    import json

    summary = json.loads((tmp_path / "run" / "summary.json").read_text())["summary"]
    # the README quotes "from activation + 8 s"
    assert summary["from_activation_plus_8s"]["cross_track_rms_m"] < 0.05
