"""The Dask engine (optional extra): same rows as the local executor; clear errors without it."""

from __future__ import annotations

import dataclasses

import pytest

from pf_offboard.errors import InputError
from pf_offboard.sweep import engine, plan
from pf_offboard.sweep.runner import execute, rows_equal

from .helpers import PAPER, tiny_spec


@pytest.mark.parametrize("address", ["", "nowhere", "tcp://host:", "tcp://:8786", "host:99999"])
def test_bad_addresses_name_the_flag(address: str) -> None:
    with pytest.raises(InputError) as exc:
        engine.check_address(address)
    assert exc.value.field == "--cluster"


def test_good_addresses() -> None:
    assert engine.check_address("local") == "local"
    assert engine.check_address("tcp://10.0.0.5:8786") == "tcp://10.0.0.5:8786"


def test_without_the_extra_the_error_says_how_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(engine, "available", lambda: False)
    with pytest.raises(InputError, match=r"pip install 'pf-offboard\[cluster\]'"):
        execute(plan.tasks(PAPER, tiny_spec(1)), cluster="local")


def test_dask_gives_the_same_rows_as_the_local_executor() -> None:
    distributed = pytest.importorskip("distributed")
    tasks = plan.tasks(PAPER, tiny_spec(3))
    tasks.append(dataclasses.replace(tasks[0], start=dataclasses.replace(tasks[0].start, index=3), config_yaml="path: 3\n"))
    # threads, not processes: the engine path (map, as_completed, ordering) without process start-up
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        rows = execute(tasks, client=client)
    serial = execute(tasks, workers=1)
    assert rows_equal(rows, serial) and serial[3]["reason"].startswith("error")
