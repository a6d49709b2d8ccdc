"""What every log writer shares: a context manager that closes, a stream that flushes, an output directory."""

from __future__ import annotations

from pathlib import Path
from types import TracebackType
from typing import IO, Any, Self

from pf_offboard.errors import InputError


def make_dir(path: str | Path, flag: str) -> Path:
    """Create the output directory ``path`` (given by ``flag``) or raise one clear :class:`InputError`."""
    p = Path(path)
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(flag, f"cannot create directory {p}: {exc.strerror or exc}") from None
    return p


class Closing:
    """``with X.open(...) as w:`` closes ``w`` on the way out, exception or not."""

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


class StreamWriter(Closing):
    """A writer that owns one open file: ``flush()`` and ``close()`` (idempotent)."""

    def __init__(self, stream: IO[Any]) -> None:
        self._stream = stream

    def flush(self) -> None:
        self._stream.flush()

    def close(self) -> None:
        if not self._stream.closed:
            self._stream.flush()
            self._stream.close()
