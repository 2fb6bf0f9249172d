"""The backfill on a Dask cluster (prefect-dask's DaskTaskRunner): the same warehouse as on one process."""

from __future__ import annotations

import distributed
import pytest
from prefect_dask import DaskTaskRunner

from flows.orchestration.backfill import backfill_flow
from tests.orchestration.conftest import END, START, assert_same, snapshot


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None, silence_logs=40) as c:
        yield c


def test_dask_workers_make_the_same_warehouse(prefect_server, cluster, clean, archive, tmp_path):
    wh = tmp_path / "wh"
    with distributed.Client(cluster.scheduler_address, set_as_default=False) as client:
        transitions = lambda: client.run_on_scheduler(lambda dask_scheduler: dask_scheduler.transition_counter)  # noqa: E731
        before = transitions()
        summary = backfill_flow.with_options(task_runner=DaskTaskRunner(address=cluster.scheduler_address))(
            config_path=str(archive / "plant.toml"), warehouse=str(wh), start=START, end=END,
            exports=str(archive / "exports"), concurrency=4, unit_days=1,
        )  # fmt: skip
        assert transitions() - before >= 3 * (3 + 2 + 6)  # the 11 tasks went through the scheduler
        assert len(client.nthreads()) == 2
    assert summary.files_ingested == 3 and summary.units_done == 6 and summary.units_failed == 0
    # same rows in every table (but the times and run ids), same bytes in every lake file
    assert_same(snapshot(wh, volatile=False), snapshot(clean[0], volatile=False))
