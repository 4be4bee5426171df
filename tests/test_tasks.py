"""hbgear.tasks: the record (fingerprint, fsynced lines, a cut line ignored), the runner in this
process and in spawned worker processes, failures keep what finished, the compile clock."""

import math
import os

import pytest

from hbgear.tasks import CompileClock, Journal, JsonLines, fingerprint, plan, run_tasks


def test_journal_states_and_a_line_cut_by_a_crash(tmp_path):
    path = tmp_path / "record.jsonl"
    mark = fingerprint("test", {"a": 1})
    assert mark.startswith("# hbgear test partial; sha256=") and mark != fingerprint("test", {"a": 2})
    journal = Journal(path, mark)
    assert journal.state() == "absent" and journal.read() == {}
    journal.start({0: {"x": 0.1}})
    journal.add(2, {"x": float("nan"), "y": [1, 2]})
    journal.close()
    with path.open("a") as fh:
        fh.write('{"task": 3, "result": {"x":')  # cut by a crash
    assert journal.state() == "same"
    done = journal.read()
    assert list(done) == [0, 2] and done[0] == {"x": 0.1} and math.isnan(done[2]["x"])
    journal.start(done)  # rewrites the valid part: the cut line is gone
    journal.add(3, 7)
    journal.close()
    again = Journal(path, mark).read()
    assert list(again) == [0, 2, 3] and again[3] == 7 and again[2]["y"] == [1, 2]
    assert len(path.read_text().splitlines()) == 4
    other = Journal(path, fingerprint("test", {"a": 2}))
    assert other.state() == "other" and other.read() == {}
    journal.remove()
    assert not path.exists()


def test_json_lines_round_trip_floats_exactly():
    codec = JsonLines()
    values = [0.1 + 0.2, 1e-300, -2.5e17, math.pi]
    back = codec.decode([codec.encode("k", values)])
    assert back == {"k": values}


def test_serial_runner_skips_finished_tasks_and_keeps_order(tmp_path):
    calls, seen = [], []

    def square(x):
        calls.append(x)
        return x * x

    tasks = {k: (k,) for k in (3, 1, 2, 0)}
    journal = Journal(tmp_path / "r.jsonl", fingerprint("squares", sorted(tasks)))
    out = run_tasks(square, tasks, journal=journal, done={1: 1, 99: 0}, progress=False,
                    on_result=lambda k, r: seen.append(k))
    assert list(out) == [3, 1, 2, 0] and out == {3: 9, 1: 1, 2: 4, 0: 0}
    assert calls == [3, 2, 0] == seen
    assert journal.read() == {1: 1, 3: 9, 2: 4, 0: 0}


def test_a_failing_task_keeps_the_finished_ones(tmp_path):
    def fails_third(x):
        if x == 2:
            raise ValueError("no")
        return x

    journal = Journal(tmp_path / "r.jsonl", fingerprint("f", 1))
    with pytest.raises(ValueError):
        run_tasks(fails_third, {k: (k,) for k in range(5)}, journal=journal, progress=False)
    assert journal.read() == {0: 0, 1: 1}


def test_worker_processes_are_other_processes_and_errors_propagate():
    assert plan(None, 1) == ("in-process", 1) and plan(3, 2) == ("processes", 2) and plan(2, 5, "tcp://x:1")[0] == "dask"
    out = run_tasks(os.getpid, {k: () for k in range(4)}, workers=2, progress=False)
    pids = set(out.values())
    assert os.getpid() not in pids and 1 <= len(pids) <= 2
    with pytest.raises(ValueError, match="math domain error"):
        run_tasks(math.sqrt, {0: (4.0,), 1: (-1.0,), 2: (9.0,)}, workers=2, progress=False)


def test_compile_clock_sees_compilation_not_execution():
    import jax
    import jax.numpy as jnp

    f = jax.jit(lambda x: jnp.sin(x) * jnp.cos(x) + x ** 3)
    with CompileClock() as first:
        f(1.0).block_until_ready()
    with CompileClock() as second:
        for _ in range(50):
            f(2.0).block_until_ready()
    assert first.seconds > 0.0 and second.seconds == 0.0
