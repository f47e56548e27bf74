"""fold_batch shared among two processes (jax.distributed on the loopback address): every
process returns every result, in input order, equal to one process folding them all."""

import os
import pickle
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import jax
import numpy as np
import pytest

from origami_jax import fold_batch, patterns
from origami_jax.processes import all_gather

jax.config.update("jax_enable_x64", True)

ROOT = Path(__file__).resolve().parents[1]

# the problems, built alike by the test and by each process: tiny patterns of one size bucket
# (one compile for the mixed list, one for the single pattern's parameter sets)
PROBLEMS = textwrap.dedent(
    """
    from origami_jax import patterns

    def mixed():
        miura = patterns.miura_ori(2, 2)
        cps = [miura] * 4 + [patterns.waterbomb(1, 1), patterns.miura_ori(2, 3)]
        return cps, [0.3, 1.0, 0.6, 0.8, 1.0, 0.5]

    ONE_PERCENTS = [0.2, 0.4, 0.6, 0.8, 1.0]
    """
)

WORKER = PROBLEMS + textwrap.dedent(
    """
    import pickle, sys, warnings
    import jax

    me, port, out = int(sys.argv[1]), sys.argv[2], sys.argv[3]
    jax.config.update("jax_enable_x64", True)
    jax.config.update("jax_num_cpu_devices", 1)  # each process its own device
    jax.distributed.initialize(
        coordinator_address=f"127.0.0.1:{port}", num_processes=2, process_id=me
    )
    from origami_jax import batch, fold_batch

    assert jax.process_count() == 2 and len(jax.local_devices()) == 1
    found = {}
    cps, percents = mixed()
    # the problems this process folds itself (the rest it gets from the other)
    run_group, folded = batch._run_group, []

    def recorded(group, *args):
        folded.extend(m.index for m in group)
        return run_group(group, *args)

    batch._run_group = recorded
    # shared by default: size buckets (mixed patterns), then one topology (one pattern)
    found["mixed"] = fold_batch(cps, percent=percents, progress=False)
    found["folded mixed"], folded[:] = sorted(folded), []
    found["one"] = fold_batch(patterns.miura_ori(2, 2), percent=ONE_PERCENTS, progress=False)
    found["folded one"] = sorted(folded)
    # each process its own problem, alone: no exchange
    found["own"] = fold_batch(cps[:1], percent=0.5 + 0.25 * me, processes=False, progress=False)
    # different problems in the two processes: both refuse
    try:
        fold_batch(cps, percent=percents[:-1] + [0.4 + 0.1 * me], progress=False)
    except ValueError as e:
        found["mismatch"] = str(e)
    # Ctrl-C in process 1 before it folds anything: it returns at once, process 0 with its
    # own share
    def interrupted(*args):
        raise KeyboardInterrupt

    batch._run_group = interrupted if me == 1 else run_group
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        done = fold_batch(cps, percent=percents, progress=False)
    found["interrupted"] = ([r is not None for r in done], [str(w.message) for w in caught])
    batch._run_group = run_group
    # the other process's device: refused (before any exchange)
    try:
        fold_batch(cps, devices=jax.devices(), progress=False)
    except ValueError as e:
        found["foreign"] = str(e)
    # process 1 fails while folding: process 0, waiting for its share, is told why
    if me == 1:
        def broken(*args):
            raise FloatingPointError("broken on purpose")

        batch._run_group = broken
    try:
        fold_batch(cps, percent=percents, progress=False)
    except (FloatingPointError, RuntimeError) as e:
        found["failed"] = f"{type(e).__name__}: {e}"
    with open(out, "wb") as f:
        pickle.dump(found, f)
    print("worker done", me)
    """
)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def two_processes(tmp_path_factory):
    """What each of two processes returned (started on the loopback address, one CPU device
    each), killed if they have not finished in 15 minutes (CI machines can be loaded)."""
    tmp = tmp_path_factory.mktemp("processes")
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    port = _free_port()
    procs, logs = [], []
    try:
        for me in range(2):
            log = open(tmp / f"log{me}.txt", "w")  # noqa: SIM115 (closed below)
            logs.append(log)
            procs.append(
                subprocess.Popen(
                    [sys.executable, "-c", WORKER, str(me), str(port), str(tmp / f"out{me}")],
                    env=env,
                    stdout=log,
                    stderr=subprocess.STDOUT,
                )
            )
        for proc in procs:
            proc.wait(timeout=900)
    finally:
        for proc in procs:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        for log in logs:
            log.close()
    texts = [(tmp / f"log{me}.txt").read_text() for me in range(2)]
    for proc, text in zip(procs, texts, strict=True):
        assert proc.returncode == 0, text[-3000:]
    return [pickle.loads((tmp / f"out{me}").read_bytes()) for me in range(2)]


def _problems() -> dict:
    space: dict = {}
    exec(PROBLEMS, space)
    return space


def _queue_order(cps: list, percents: list) -> list[int]:
    """The problems' indices in fold_batch's queue order: those that fold furthest first."""
    return sorted(range(len(cps)), key=lambda k: -percents[k] * max(abs(cps[k].mesh.target)))


def _assert_same(got: list, want: list, cps: list, percents: list) -> None:
    """``got`` (from a process) equals ``want`` (this process's fold_batch), in input order."""
    assert len(got) == len(want) == len(cps)
    for r, w, cp, pc in zip(got, want, cps, percents, strict=True):
        # input order: each result is its problem's (its pattern, its percent)
        np.testing.assert_array_equal(r.pattern.vertices, cp.vertices)
        assert r.percent == pc == w.percent
        assert r.positions.shape == w.positions.shape
        assert np.max(np.abs(r.positions - w.positions)) <= 1e-9
        assert r.status == w.status and r.converged
        assert r.iterations == w.iterations
        assert r.fold_angle_error_max == pytest.approx(w.fold_angle_error_max, abs=1e-9)


def test_every_process_returns_every_result_in_input_order(two_processes):
    space = _problems()
    cps, percents = space["mixed"]()
    want = fold_batch(cps, percent=percents, progress=False)
    for found in two_processes:
        _assert_same(found["mixed"], want, cps, percents)
    # each folded half of them, every other one in queue order
    order = _queue_order(cps, percents)
    for me, found in enumerate(two_processes):
        assert found["folded mixed"] == sorted(order[me::2])


def test_one_topology_shared_among_processes(two_processes):
    space = _problems()
    cp, percents = patterns.miura_ori(2, 2), space["ONE_PERCENTS"]
    want = fold_batch(cp, percent=percents, progress=False)
    for found in two_processes:
        _assert_same(found["one"], want, [cp] * len(percents), percents)
    assert two_processes[0]["folded one"] == [0, 2, 4]  # percents 1.0, 0.6 and 0.2
    assert two_processes[1]["folded one"] == [1, 3]


def test_processes_false_folds_alone(two_processes):
    cp = _problems()["mixed"]()[0][0]
    for me, found in enumerate(two_processes):
        (want,) = fold_batch(cp, percent=0.5 + 0.25 * me, progress=False)
        _assert_same(found["own"], [want], [cp], [0.5 + 0.25 * me])


def test_processes_given_other_problems_refuse(two_processes):
    for found in two_processes:
        assert "processes [1] were given other problems" in found["mismatch"]


def test_an_interrupted_process_hands_on_what_it_has(two_processes):
    cps, percents = _problems()["mixed"]()
    order = _queue_order(cps, percents)
    done, caught = two_processes[0]["interrupted"]
    assert done == [k in order[0::2] for k in range(len(cps))]
    assert caught == [
        "fold_batch() interrupted in process [1]: 3 of 6 problems have results, the rest are None"
    ]
    done, caught = two_processes[1]["interrupted"]
    assert done == [False] * len(cps)
    assert caught == ["fold_batch() interrupted: 0 of 6 problems have results, the rest are None"]


def test_another_process_devices_refused(two_processes):
    for found in two_processes:
        assert "belong to other processes" in found["foreign"]


def test_a_failed_process_stops_the_others(two_processes):
    assert two_processes[1]["failed"] == "FloatingPointError: broken on purpose"
    assert two_processes[0]["failed"] == (
        "RuntimeError: fold_batch(): process 1 failed: FloatingPointError: broken on purpose"
    )


def test_one_process_gathers_its_own_bytes():
    assert jax.process_count() == 1
    assert all_gather(b"mine") == [b"mine"]
