"""The command line starts light: ``--help`` and ``--version`` import no numpy / scipy / pymavlink
(their wall time is a ``pf-offboard bench`` figure, not asserted here); each sub-command's module
is imported only when that sub-command runs."""

from __future__ import annotations

import subprocess
import sys

import pytest

PROBE = """
import contextlib, io, sys
from pf_offboard.cli import main
out = io.StringIO()
with contextlib.redirect_stdout(out):
    try:
        main({argv!r})
    except SystemExit:
        pass
heavy = [m for m in ("numpy", "scipy", "pymavlink", "matplotlib", "yaml") if m in sys.modules]
print(repr(heavy)); print(out.getvalue())
"""


def _probe(argv: list[str]) -> tuple[list[str], str]:
    done = subprocess.run([sys.executable, "-c", PROBE.format(argv=argv)], capture_output=True, text=True, check=True)
    first, _, rest = done.stdout.partition("\n")
    return eval(first), rest  # noqa: S307  (our own repr of a list of names)


@pytest.mark.parametrize("argv", [["--help"], ["--version"]])
def test_help_and_version_import_nothing_heavy(argv: list[str]) -> None:
    heavy, out = _probe(argv)
    assert heavy == [], heavy
    assert ("pf-offboard" in out) and (argv != ["--help"] or "fly" in out and "identify" in out)


def test_version() -> None:
    import pf_offboard

    _, out = _probe(["--version"])
    assert out.strip() == f"pf-offboard {pf_offboard.__version__}"


def test_a_sub_command_help_imports_only_its_module() -> None:
    heavy, out = _probe(["configs", "--help"])
    assert "scipy" not in heavy and "numpy" not in heavy, heavy
    assert "usage: pf-offboard configs" in out
