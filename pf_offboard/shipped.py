"""The configs shipped inside the package (``pf_offboard/configs/*.yaml``), found by name.

``--config`` accepts a file path or the name of a shipped config (``paper``, ``paper.yaml``):
an existing file wins, then a shipped name. They are package data, so they are there after
``pip install`` wherever the command runs. ``pf-offboard configs`` lists them and
``pf-offboard init`` writes an editable copy.
"""

from __future__ import annotations

import importlib.resources
import os
import re
from dataclasses import dataclass
from pathlib import Path

from pf_offboard.errors import InputError

PACKAGE = "pf_offboard"
DIRECTORY = "configs"


@dataclass(frozen=True)
class ShippedConfig:
    """One shipped config: ``name`` (file stem), ``description`` (its first comment line), ``path``."""

    name: str
    description: str
    path: Path


def _directory() -> Path:
    """The packaged configs directory (a real directory for a regular or editable install)."""
    root = importlib.resources.files(PACKAGE) / DIRECTORY
    return Path(str(root))


def _description(text: str, width: int = 100) -> str:
    """The first sentence of the file's leading comment block, cut to ``width`` characters."""
    words: list[str] = []
    for line in text.splitlines():
        stripped = line.strip()
        if not stripped.startswith("#"):
            break
        words += stripped.lstrip("#").split()
    sentence = " ".join(words)
    end = re.search(r"(?<!Fig)(?<!e\.g)\.\s+(?=[A-Z])", sentence)  # "Fig. 4" ends no sentence
    if end is not None:
        sentence = sentence[: end.start() + 1]
    if len(sentence) > width:
        sentence = sentence[: width - 1].rsplit(" ", 1)[0].rstrip(",;:") + "…"
    return sentence


def shipped_configs() -> list[ShippedConfig]:
    """Every shipped config, sorted by name."""
    directory = _directory()
    out = []
    for p in sorted(directory.glob("*.yaml")):
        out.append(ShippedConfig(p.stem, _description(p.read_text(encoding="utf-8")), p))
    return out


def shipped_config(name: str) -> ShippedConfig | None:
    """The shipped config called ``name`` (with or without ``.yaml``), or None."""
    stem = name.removesuffix(".yaml").removesuffix(".yml")
    return next((c for c in shipped_configs() if c.name == stem), None)


def resolve_config(text: str | os.PathLike[str], flag: str = "--config") -> Path:
    """A ``--config`` value: an existing file, else a shipped config's name. InputError otherwise."""
    p = Path(text)
    if p.is_file():
        return p
    if p.is_dir():
        raise InputError(flag, f"{p} is a directory, not a config file")
    text = os.fspath(text)
    if os.sep not in text and "/" not in text:
        found = shipped_config(text)
        if found is not None:
            return found.path
    if os.sep in text or "/" in text:
        raise InputError(flag, f"no such file: {text}")
    names = ", ".join(c.name for c in shipped_configs())
    raise InputError(flag, f"no such file: {text}, and not a shipped config (shipped: {names}; see pf-offboard configs)")
