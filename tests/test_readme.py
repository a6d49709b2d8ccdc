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
