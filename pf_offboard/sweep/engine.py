"""Sweep flights on a Dask cluster (``pf-offboard sweep --cluster ADDRESS``).

Dask's ``distributed`` is the optional ``cluster`` extra (``pip install '.[cluster]'``): pure
Python, it installs with pip on every Python this project supports, and its ``LocalCluster`` runs
the same scheduler and worker processes on one machine (``--cluster local``), which is what the
tests and the benchmark use. ``ADDRESS`` is an existing scheduler (``tcp://host:8786``); its
workers need ``pf_offboard`` installed (the same version: each task is a pickled
:class:`~pf_offboard.sweep.runner.FlightTask` run by :func:`~pf_offboard.sweep.runner.run_flight`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from pf_offboard.errors import InputError

CONNECT_TIMEOUT_S = 15.0
INSTALL_HINT = "needs the optional Dask extra: pip install 'pf-offboard[cluster]' (dask.distributed)"


def check_address(address: str) -> str:
    """``local`` or a scheduler address ``[tcp://]host:port``; InputError naming ``--cluster``."""
    if address == "local":
        return address
    rest = address.split("://", 1)[1] if "://" in address else address
    host, _, port = rest.rpartition(":")
    if not host or not port.isdigit() or not 1 <= int(port) <= 65535:
        raise InputError("--cluster", f"expected 'local' or a Dask scheduler address like tcp://host:8786, got {address!r}")
    return address


def available() -> bool:
    """Whether the optional Dask extra is installed."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


def run_on_dask(tasks: Sequence[Any], fn: Callable[[Any], dict[str, Any]], address: str | None, workers: int,
                client: Any = None) -> Iterator[tuple[Any, dict[str, Any]]]:  # fmt: skip
    """``(task.key, fn(task))`` for every task, in completion order, run on the cluster at
    ``address`` (``local``: a LocalCluster of ``workers`` single-threaded processes) or on
    ``client``, an existing ``distributed.Client`` (left open)."""
    if client is None:
        if address is None:
            raise InputError("--cluster", "no address given")
        check_address(address)
        if not available():
            raise InputError("--cluster", INSTALL_HINT)
    import distributed

    owned: list[Any] = []
    if client is None:
        if address == "local":
            cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                               dashboard_address=None, silence_logs=logging.ERROR)  # fmt: skip
            owned.append(cluster)
            client = distributed.Client(cluster)
        else:
            try:
                client = distributed.Client(address, timeout=CONNECT_TIMEOUT_S)
            except (OSError, TimeoutError) as exc:
                raise InputError("--cluster", f"cannot reach a Dask scheduler at {address}: {exc}") from None
        owned.insert(0, client)
    try:
        futures = client.map(fn, list(tasks), pure=False)
        keys = {f.key: t.key for f, t in zip(futures, tasks)}
        for fut in distributed.as_completed(futures):
            yield keys[fut.key], fut.result()
    finally:
        for thing in owned:
            thing.close()
