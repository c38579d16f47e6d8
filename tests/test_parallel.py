"""Executors (cappe.parallel): serial, threads, local processes and a real Dask cluster give identical results.

The Dask test starts a ``dask scheduler`` and two ``dask worker`` processes on loopback (the installed console
scripts), runs the modal engine and a small automated identification there, and compares with the serial run
for the same seed: every number must be equal, not close.
"""

from __future__ import annotations

import json
import os
import platform
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from cappe.estimate._automated import AutomatedIdentification
from cappe.modal import ModalEngine
from cappe.model import NumericModel, load_model
from cappe.parallel import (
    Executor,
    blas_threads,
    command_blas_threads,
    map_chunks,
    shared_loads,
    single_threaded_blas,
)

BENCH = Path(__file__).parent / "data" / "bench-slide.yaml"
POSITIONS = [{"z": -0.2}, {"z": 0.0}, {"z": 0.3}]


def _square_chunk(offset: float):
    # a closure: processes and Dask must ship it by value
    def work(s: slice) -> list[float]:
        return [offset + k * k for k in range(s.start, s.stop)]

    return work


def _warning_chunk(odd: str):
    # a closure, shipped by value: warns on the odd chunks
    def work(s: slice) -> int:
        import warnings

        if s.start % 2:
            warnings.warn(f"chunk {s.start} {odd}", UserWarning, stacklevel=1)
        return s.start

    return work


@pytest.mark.parametrize("kind", ["serial", "processes"])
def test_warnings_raised_in_workers_reach_the_caller(kind):
    # a worker process's warnings were lost: the user saw them on a serial run only
    with Executor(kind, n_workers=2) as ex, pytest.warns(UserWarning, match="chunk") as caught:
        out = ex.map(_warning_chunk("is odd"), [slice(k, k + 1) for k in range(5)])
    assert out == [0, 1, 2, 3, 4]
    assert [str(w.message) for w in caught] == ["chunk 1 is odd", "chunk 3 is odd"]


@pytest.mark.parametrize("kind", ["serial", "threads", "processes"])
def test_local_executors_keep_order_and_report_each_chunk(kind):
    seen = []
    with Executor(kind, n_workers=2) as ex:
        out = ex.map(_square_chunk(0.5), [slice(0, 3), slice(3, 4), slice(4, 7)], done=seen.append)
    assert out == [[0.5, 1.5, 4.5], [9.5], [16.5, 25.5, 36.5]]
    assert sorted(s.start for s in seen) == [0, 3, 4]


def test_map_chunks_results_do_not_depend_on_the_executor():
    expected = [float(k * k) for k in range(11)]
    for executor in ("serial", "threads", "processes"):
        parts = map_chunks(_square_chunk(0.0), 11, chunk_size=4, executor=executor, n_workers=2)
        assert [v for part in parts for v in part] == expected


def test_executor_errors():
    with pytest.raises(ValueError, match="executor must be 'serial', 'threads', 'processes' or a Dask scheduler"):
        Executor("gpu")
    with pytest.raises(ValueError, match="n_workers must be a positive integer"):
        Executor("threads", n_workers=0)
    with pytest.raises(ValueError, match="has no Dask client"):
        _ = Executor("threads").client
    # an exception in a worker process reaches the caller
    with pytest.raises(ZeroDivisionError), Executor("processes", n_workers=2) as ex:
        ex.map(lambda s: 1 / 0, [slice(0, 1), slice(1, 2)])


def _blas_threads() -> list[int]:
    return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]


def test_blas_limit_is_restored_after_overlapping_threads():
    # the limit is process-wide: a thread that enters and leaves while another still works must not lift it
    # (read here, in the thread that entered first)
    before = _blas_threads()
    with single_threaded_blas():
        assert all(n == 1 for n in _blas_threads())
        with single_threaded_blas():  # nested in the same thread
            pass
        inner = threading.Thread(target=_enter_and_leave)
        inner.start()
        inner.join()
        assert all(n == 1 for n in _blas_threads())
    assert _blas_threads() == before


def _enter_and_leave() -> None:
    with single_threaded_blas():
        pass


def test_blas_threads_sets_the_count_and_the_load_variables_and_restores_both(monkeypatch):
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "7")
    monkeypatch.delenv("MKL_NUM_THREADS", raising=False)
    with threadpool_limits(limits=1, user_api="blas"):
        with blas_threads(2):
            assert set(_blas_threads()) == {2}
            assert (os.environ["OPENBLAS_NUM_THREADS"], os.environ["MKL_NUM_THREADS"]) == ("2", "2")
            with single_threaded_blas():  # an executor's map inside a command
                assert set(_blas_threads()) == {1}
            assert set(_blas_threads()) == {2}
        assert set(_blas_threads()) == {1}
        with blas_threads(None):  # 'auto': nothing changes
            assert set(_blas_threads()) == {1}
            assert os.environ["OPENBLAS_NUM_THREADS"] == "7"
    assert os.environ["OPENBLAS_NUM_THREADS"] == "7"
    assert "MKL_NUM_THREADS" not in os.environ
    with pytest.raises(ValueError, match=r"limit must be a positive integer or None; got 0"), blas_threads(0):
        pass


@pytest.mark.parametrize(("value", "threads"), [(None, 1), ("", 1), ("3", 3), ("AUTO", None), (" auto ", None)])
def test_command_blas_threads_reads_the_variable(value, threads):
    assert command_blas_threads({} if value is None else {"CAPPE_BLAS_THREADS": value}) == threads


@pytest.mark.parametrize("value", ["0", "-2", "2.0", "many"])
def test_command_blas_threads_refuses_other_values(value):
    with pytest.raises(ValueError, match=rf"CAPPE_BLAS_THREADS must be a positive number of threads or 'auto'; "
                                         rf"got '{re.escape(value)}'"):
        command_blas_threads({"CAPPE_BLAS_THREADS": value})


@pytest.fixture(scope="module")
def bench() -> NumericModel:
    return NumericModel(load_model(BENCH))


def _identify(bench: NumericModel, reference, executor) -> AutomatedIdentification:
    return AutomatedIdentification(bench, n_gsa=16, n_opt=3, rng=5, validation={"z": -0.2}, n_permutations=0,
                                   n_workers=2, executor=executor).fit(reference)


def _same(a: AutomatedIdentification, b: AutomatedIdentification) -> None:
    np.testing.assert_array_equal(a.estimate_.values, b.estimate_.values)
    np.testing.assert_array_equal(a.gsa_.sobol.ST, b.gsa_.sobol.ST)
    for sa, sb in zip(a.subproblems_, b.subproblems_, strict=True):
        np.testing.assert_array_equal(sa.values, sb.values)


@pytest.fixture(scope="module")
def reference(bench):
    truth = {"me_kx": 7.1e7, "lgs_ky": 3.4e8, "me_by": 1.1e4}
    return ModalEngine(bench).modal_data(POSITIONS, params=truth)


@pytest.fixture(scope="module")
def serial_run(bench, reference):
    return _identify(bench, reference, "serial")


def test_identification_in_processes_equals_serial(bench, reference, serial_run):
    _same(_identify(bench, reference, "processes"), serial_run)


@pytest.fixture(scope="module")
def dask_cluster(tmp_path_factory):
    """A scheduler and two single-threaded workers on loopback, as a user would start them."""
    folder = tmp_path_factory.mktemp("dask")
    scheduler_file = folder / "scheduler.json"
    bindir = Path(sys.executable).parent
    env = {**os.environ, "DASK_DISTRIBUTED__WORKER__DAEMON": "False"}
    procs = [subprocess.Popen([str(bindir / "dask"), "scheduler", "--host", "127.0.0.1", "--port", "0",
                               "--no-dashboard", "--scheduler-file", str(scheduler_file)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, cwd=folder)]
    try:
        deadline = time.monotonic() + 300  # hang guards, not speed bounds: a loaded CI machine starts dask slowly
        while not scheduler_file.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        address = json.loads(scheduler_file.read_text())["address"]
        for _ in range(2):
            procs.append(subprocess.Popen([str(bindir / "dask"), "worker", address, "--nthreads", "1",
                                           "--no-dashboard", "--host", "127.0.0.1"],
                                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, cwd=folder))
        with Executor(address) as ex:
            ex.client.wait_for_workers(2, timeout=300)
        yield address
    finally:
        for proc in procs[::-1]:
            proc.terminate()
        for proc in procs:
            proc.wait(timeout=120)


@pytest.mark.slow
def test_dask_cluster_gives_the_serial_results(bench, reference, serial_run, dask_cluster):
    with Executor(dask_cluster) as ex:
        seen = []
        parts = ex.map(_square_chunk(2.0), [slice(0, 2), slice(2, 5)], done=seen.append)
        assert parts == [[2.0, 3.0], [6.0, 11.0, 18.0]]
        assert len(seen) == 2
        # the modal engine's chunks on the cluster: identical to one thread here
        params = bench.nominal * np.random.default_rng(0).uniform(0.8, 1.2, size=(40, bench.nominal.size))
        remote = ModalEngine(bench, chunk_size=8, executor=ex).evaluate(params, {"z": 0.1}, exact=True)
        local = ModalEngine(bench, chunk_size=40, executor="serial").evaluate(params, {"z": 0.1}, exact=True)
        np.testing.assert_array_equal(remote.frequency, local.frequency)
        np.testing.assert_array_equal(remote.poles, local.poles)
        # the whole pipeline, given as an address (the estimator opens and closes its own client)
    _same(_identify(bench, reference, dask_cluster), serial_run)


@pytest.mark.slow
def test_dask_ships_the_model_once_per_worker_not_per_task(bench, dask_cluster):
    params = bench.nominal * np.random.default_rng(1).uniform(0.8, 1.2, size=(40, bench.nominal.size))
    with Executor(dask_cluster) as ex:
        before = ex.client.run(shared_loads)
        engine = ModalEngine(bench, chunk_size=4, executor=ex)
        batches = [engine.evaluate(params, position) for position in POSITIONS]  # 3 maps of 10 tasks
        after = ex.client.run(shared_loads)
    local = ModalEngine(bench, executor="serial")
    for batch, position in zip(batches, POSITIONS, strict=True):
        np.testing.assert_array_equal(batch.frequency, local.evaluate(params, position).frequency)
    # per worker that ran tasks: the engine and its model, each unpickled once for the 30 tasks of the 3 maps
    # (before: once per map for every worker, or once per task)
    assert not any(before.values())  # the other tests' executors dropped theirs when they closed
    assert any(after.values())
    for counts in after.values():
        assert sorted(counts.values()) in ([], [1, 1])
    # a worker's warnings reach the caller, in item order
    with Executor(dask_cluster) as ex, pytest.warns(UserWarning, match="chunk") as caught:
        assert ex.map(_warning_chunk("on a worker"), [slice(k, k + 1) for k in range(4)]) == [0, 1, 2, 3]
    assert [str(w.message) for w in caught] == ["chunk 1 on a worker", "chunk 3 on a worker"]
    # closing the executor dropped the workers' copies
    with Executor(dask_cluster) as ex:
        assert not any(ex.client.run(shared_loads).values())


def _validate_against_truth(model: NumericModel, reference, truth: dict[str, float]):
    # a closure, shipped by value (its model once per executor): the validation of the truth at one position
    def work(k: int) -> float:
        from cappe.estimate._validation import validate_identification

        result = validate_identification(model=model, params=model.nominal, reference=reference,
                                         position=POSITIONS[k], truth=truth, n_freq=50)
        return float(np.nanmean(result.frac))

    return work


def _models_alive():
    # a closure, shipped by value: (NumericModels alive, truth FRFs kept) in the process, after a collection
    def probe() -> tuple[int, int]:
        import gc

        from cappe.estimate._validation import _truth_receptance
        from cappe.model import NumericModel

        gc.collect()
        cache = _truth_receptance
        kept = len(cache) if hasattr(cache, "__len__") else cache.cache_info().currsize  # the lru_cache before
        return sum(isinstance(o, NumericModel) for o in gc.get_objects()), kept

    return probe


@pytest.mark.slow
def test_closing_a_dask_executor_releases_the_workers_truth_frfs(bench, reference, dask_cluster):
    truth = {"me_kx": 7.1e7, "lgs_ky": 3.4e8, "me_by": 1.1e4}
    with Executor(dask_cluster) as ex:
        assert all(n == 0 for n, _ in ex.client.run(_models_alive()).values())
        fracs = ex.map(_validate_against_truth(bench, reference, truth), [0, 1, 2, 0])
        during = ex.client.run(_models_alive())
    assert np.all(np.isfinite(fracs))
    assert any(n > 0 and kept > 0 for n, kept in during.values())  # the workers held the model and its FRFs
    with Executor(dask_cluster) as ex:
        after = ex.client.run(_models_alive())
    # before: the validation's FRF cache kept each worker's model copy (and its FRFs) after the executor closed
    assert all(n == 0 and kept == 0 for n, kept in after.values()), after


def _page_faults_per_array(mib: int):
    # a closure, shipped by value: the page faults of allocating, filling and freeing an array of `mib` MiB
    def work(s: slice) -> float:
        import resource

        for _ in range(5):  # the first arrays may fault the heap in
            np.ones(mib << 17).sum()
        before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
        for _ in range(40):
            np.ones(mib << 17).sum()
        return (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / 40

    return work


@pytest.mark.slow
@pytest.mark.skipif(sys.platform != "linux" or platform.libc_ver()[0] != "glibc", reason="glibc only")
def test_dask_workers_keep_freed_memory_despite_the_nanny_trim_threshold(dask_cluster):
    # Dask's nanny starts each worker with MALLOC_TRIM_THRESHOLD_=65536, which also freezes glibc's mmap threshold
    # at 128 KiB: every 1 MiB array was 256 fresh pages (and the worker spent ~2x a plain process's CPU)
    with Executor(dask_cluster) as ex:
        assert set(ex.client.run(os.getenv, "MALLOC_TRIM_THRESHOLD_").values()) == {"65536"}
        faults = ex.map(_page_faults_per_array(1), [slice(0, 1), slice(1, 2)])
    assert max(faults) < 16, faults  # 256 per array before


@pytest.mark.skipif(sys.platform != "linux" or platform.libc_ver()[0] != "glibc", reason="glibc only")
def test_allocator_is_tuned_once_unless_the_user_set_glibc_variables():
    code = "from cappe.parallel import retain_freed_memory as r; print(r(), r())"
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_") and k != "GLIBC_TUNABLES"}
    tuned = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert tuned.stdout.split() == ["True", "True"]
    for extra in ({"MALLOC_TRIM_THRESHOLD_": "1000000"}, {"GLIBC_TUNABLES": "glibc.malloc.trim_threshold=1000000"}):
        left = subprocess.run([sys.executable, "-c", code], env={**env, **extra}, capture_output=True, text=True,
                              check=True)
        assert left.stdout.split() == ["False", "False"], extra


def _without_seconds(doc):
    """A result document without its timings (the stages', each subproblem's)."""
    if isinstance(doc, dict):
        return {k: _without_seconds(v) for k, v in doc.items() if k not in ("timings", "cpu_timings", "seconds")}
    if isinstance(doc, list):
        return [_without_seconds(v) for v in doc]
    return doc


@pytest.mark.slow
@pytest.mark.extended(reason=(
    "a whole identification on the three-axis machine (61 unknowns, 162 DOF) on a LocalCluster; the same contract on "
    "a smaller model: test_dask_cluster_gives_the_serial_results"))
def test_three_axis_identification_on_a_local_cluster_equals_serial():
    from distributed import LocalCluster

    from cappe.estimate import ParameterSpace

    machine = NumericModel(load_model("builtin:three-axis-machine-tool"))
    space = ParameterSpace.from_model(machine)
    truth = space.mapping(space.lower * (space.upper / space.lower) ** np.random.default_rng(3).uniform(size=space.n))
    positions = [{"x": -0.6, "y": 0.4, "z": -0.2}, {"x": 0.6, "y": 1.2, "z": 0.2}]
    reference = ModalEngine(machine, n_modes=10).modal_data(positions, params=truth)

    def identify(executor) -> AutomatedIdentification:
        return AutomatedIdentification(machine, n_gsa=4, n_opt=2, rng=2, validation=positions[0], n_permutations=2,
                                       exact=False, executor=executor).fit(reference)

    serial = identify("serial")
    # no dashboard, and the scheduler's HTTP server on a free port: its default, 8787, may be taken by another
    # cluster on the machine, and distributed's warning about it fails the test (filterwarnings = error)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                      scheduler_kwargs={"dashboard_address": ":0"}) as cluster:
        with Executor(cluster.scheduler_address) as ex:
            remote = identify(ex)
            loads = ex.client.run(shared_loads)
    _same(remote, serial)
    # the whole result file but its wall and CPU seconds (json: NaN equals NaN)
    docs = [_without_seconds(run.result_.to_dict()) for run in (remote, serial)]
    assert json.dumps(docs[0], sort_keys=True) == json.dumps(docs[1], sort_keys=True)
    # the model and the engines of the GSA and the subproblems: each unpickled at most once per worker
    assert all(set(counts.values()) <= {1} for counts in loads.values())
