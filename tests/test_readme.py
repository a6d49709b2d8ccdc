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


def test_readme_real_autopilot_table_is_generated_from_its_data():
    import importlib.util

    spec = importlib.util.spec_from_file_location("gen_readme_table", ROOT / "scripts" / "gen_readme_table.py")
    gen = importlib.util.module_from_spec(spec)
    assert spec.loader is not None
    spec.loader.exec_module(gen)
    import json

    data = json.loads((ROOT / "docs" / "data" / "real_sitl.json").read_text())
    assert gen.block((ROOT / "README.md").read_text()) == gen.render(data)
    assert gen.main(["--check"]) == 0


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
