"""Sweeps on a dask.distributed cluster (``derods compare --dask ADDRESS``,
derods/bench/sweep.py's dask_executor): a local cluster of two worker processes, started
here, runs a small plan; its records are those of the same plan run in this process, but
for the timing fields."""

from __future__ import annotations

import json

import pytest

import derods
from derods.__main__ import main
from derods.bench import sweep

distributed = pytest.importorskip("distributed", reason="dask.distributed is not installed: pip install 'derods[dask]'")


def _plan():
    # Four short jobs (300 steps each): two resolutions x two steps of the stability case.
    return sweep.plan(["stability"], ["der"], [8, 12], [1e-3, 1e-2], young=1e7)


def _derods_file():
    import derods

    return derods.__file__


@pytest.fixture(scope="module")
def cluster():
    # The workers are spawned processes: multiprocessing hands them this process's sys.path,
    # so they import derods from where this test does (checked below).
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as c:
        yield c


def test_the_workers_run_this_derods(cluster):
    with distributed.Client(cluster) as client:
        files = client.run(_derods_file)
    assert len(files) == 2 and set(files.values()) == {derods.__file__}


def _by_key(records):
    return {sweep.record_key(r): sweep.without_timing(r) for r in records}


def test_compare_on_a_dask_cluster_gives_the_local_records(cluster, tmp_path, capsys):
    jobs = _plan()
    assert len(jobs) == 4
    local = tmp_path / "local.jsonl"
    assert sweep.sweep(jobs, local, progress=False) == 4
    remote = tmp_path / "dask.jsonl"
    code = main(["compare", "--cases", "stability", "--backends", "der", "--n-edges", "8,12", "--dt", "1e-3,1e-2",
                 "--young", "1e7", "--dask", cluster.scheduler_address, "--results", str(remote),
                 "--report-dir", str(tmp_path / "report")])
    assert code == 0
    capsys.readouterr()
    lines = remote.read_text().splitlines()
    assert len(lines) == 4 and all(json.loads(line) for line in lines)  # whole lines, one per record
    ran, want = _by_key(sweep.load(remote)), _by_key(sweep.load(local))
    assert ran.keys() == want.keys() == {j.key() for j in jobs}
    assert ran == want
    assert all(r["stable"] for r in want.values())
    # Resumable as the local sweep: nothing left to run.
    with sweep.dask_executor(cluster.scheduler_address) as ex:
        assert sweep.sweep(jobs, remote, ex, progress=False) == 0


def test_dask_and_workers_together_are_refused(capsys):
    assert main(["compare", "--dask", "tcp://127.0.0.1:1", "--workers", "2", "--cases", "stability",
                 "--backends", "der", "--n-edges", "8"]) == 2
    assert "give one of them" in capsys.readouterr().err


def test_no_scheduler_is_a_one_line_error(tmp_path, capsys):
    with pytest.raises(ValueError, match="no dask scheduler reached"):
        with sweep.dask_executor("tcp://127.0.0.1:9", wait_s=2.0):
            pass
