"""`--version` answers on the top level and in every subcommand (a bug report names it)."""

import pytest

from pf_offboard import __version__
from pf_offboard.cli import COMMANDS, main


@pytest.mark.parametrize("argv", [["--version"]] + [[name, "--version"] for name, _, _ in COMMANDS])
def test_version_everywhere(argv, capsys) -> None:
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 0
    assert capsys.readouterr().out.strip() == f"pf-offboard {__version__}"
