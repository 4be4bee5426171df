"""The figure helper process of ``hbgear frc`` (:mod:`hbgear.outputs.drawing`): the same files as
drawing in-process, every figure drawn once by one of the two, failures raised here, a dead
helper's figures drawn here."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest

from hbgear.outputs.drawing import FigureDrawer, FigureJob, HelperFailed
from hbgear.outputs.plots import harris_figure


def _jobs(directory, count=6):
    torques = np.linspace(20.0, 200.0, 7)
    return [FigureJob(harris_figure, (torques, 1.0 + 0.1 * k + np.sqrt(torques), 100.0, f"map {k}"), {},
                      directory / f"harris_{k}.png", {"dpi": 60}) for k in range(count)]


def _wait_ready(drawer):
    """Let the helper finish its imports, so that it takes part in the next draw."""
    assert drawer.wait_ready(120.0)


def test_the_helper_draws_the_same_files_as_this_process_and_each_figure_once(tmp_path):
    here, there = tmp_path / "here", tmp_path / "there"
    here.mkdir()
    there.mkdir()
    with FigureDrawer(helper=False) as plain:
        expected = plain.draw(_jobs(here))
    with FigureDrawer(helper=True) as drawer:
        assert drawer.has_helper
        _wait_ready(drawer)
        paths = drawer.draw(_jobs(there))
        by_helper = drawer.drawn_by_helper
    assert [p.name for p in paths] == [p.name for p in expected]
    assert 1 <= by_helper <= len(paths)  # both processes drew (the helper at least one)
    for a, b in zip(expected, paths):
        assert a.read_bytes() == b.read_bytes(), a.name
    assert sorted(p.name for p in there.iterdir()) == sorted(p.name for p in expected)  # no temporary left


def test_the_helper_starts_while_this_process_works_and_finish_draws_the_rest(tmp_path):
    """start() hands the list over and returns at once; the helper draws meanwhile (here: all of
    them, this process being busy); finish() draws what is left and returns every path."""
    import time

    with FigureDrawer(helper=True) as drawer:
        _wait_ready(drawer)
        jobs = _jobs(tmp_path, 3)
        drawer.start(jobs)
        deadline = time.monotonic() + 120.0
        while not all(job.path.exists() for job in jobs) and time.monotonic() < deadline:
            time.sleep(0.05)  # "writing the tables"
        assert all(job.path.exists() for job in jobs)
        paths = drawer.finish()
        assert drawer.drawn_by_helper == 3
        assert paths == [job.path for job in jobs]
        with pytest.raises(RuntimeError):
            drawer.finish()  # nothing started
        drawer.start(_jobs(tmp_path, 2))
        with pytest.raises(RuntimeError):
            drawer.start(_jobs(tmp_path, 2))  # the last start is not finished
        assert len(drawer.finish()) == 2


def test_a_figure_that_fails_in_the_helper_raises_here_after_the_others(tmp_path):
    jobs = _jobs(tmp_path, 4)
    jobs[0] = FigureJob(harris_figure, jobs[0].args, {}, tmp_path / "missing" / "harris_0.png", {"dpi": 60})
    with FigureDrawer(helper=True) as drawer:
        _wait_ready(drawer)
        with pytest.raises(FileNotFoundError):
            drawer.draw(jobs)
        assert drawer.drawn_by_helper >= 1  # the helper took the first (failing) figure
    assert sorted(p.name for p in tmp_path.glob("*.png")) == ["harris_1.png", "harris_2.png", "harris_3.png"]


def test_a_dead_helper_leaves_its_figures_to_this_process(tmp_path):
    with FigureDrawer(helper=True) as drawer:
        os.kill(drawer._process.pid, signal.SIGKILL)
        drawer._process.wait(10)
        paths = drawer.draw(_jobs(tmp_path, 3))
        assert drawer.drawn_by_helper == 0 and not drawer.has_helper
    assert all(p.exists() for p in paths)


def test_without_a_helper_everything_is_drawn_here(tmp_path, monkeypatch):
    monkeypatch.setenv("HBGEAR_FIGURE_PROCESS", "0")
    with FigureDrawer() as drawer:
        assert not drawer.has_helper
        paths = drawer.draw(_jobs(tmp_path, 2))
    assert all(p.exists() for p in paths)


def test_an_exception_that_does_not_pickle_comes_back_as_helper_failed():
    from hbgear.outputs.drawing import _failure

    class Local(Exception):  # a local class: pickling it fails
        pass

    error = _failure(Local("bad figure"))
    import pickle

    exc = pickle.loads(error)
    assert isinstance(exc, HelperFailed) and "Local: bad figure" in str(exc)


def test_hbgear_frc_writes_the_same_files_with_the_helper_as_without(tmp_path, monkeypatch):
    from pathlib import Path

    from hbgear.cli import main
    from hbgear.outputs import drawing

    seen = []
    start, finish = drawing.FigureDrawer.start, drawing.FigureDrawer.finish

    def start_when_ready(self, jobs):
        if self.has_helper:
            assert self.wait_ready(120.0)
        start(self, jobs)

    def finish_and_count(self):
        paths = finish(self)
        seen.append((self.has_helper, self.drawn_by_helper, len(paths)))
        return paths

    monkeypatch.setattr(drawing.FigureDrawer, "start", start_when_ready)
    monkeypatch.setattr(drawing.FigureDrawer, "finish", finish_and_count)
    config = Path(__file__).resolve().parents[1] / "examples" / "paper_table1.toml"
    sets = ["solver.harmonics=8", "solver.time_samples=64", "sweep.speed_rpm_start=12000", "sweep.speed_rpm_stop=12600"]
    outs = {}
    for flag in ("0", "1"):
        monkeypatch.setenv("HBGEAR_FIGURE_PROCESS", flag)
        out = outs[flag] = tmp_path / f"helper{flag}"
        argv = ["frc", str(config), "--out", str(out), "--no-progress"]
        for s in sets:
            argv += ["--set", s]
        assert main(argv) == 0
    assert seen[0] == (False, 0, 5) and seen[1][0] and seen[1][1] >= 1 and seen[1][2] == 5
    names = sorted(p.name for p in outs["0"].iterdir())
    assert names == sorted(p.name for p in outs["1"].iterdir())
    for name in names:
        if name != "frc.json":  # its timings differ
            assert (outs["0"] / name).read_bytes() == (outs["1"] / name).read_bytes(), name


def test_a_helper_left_unused_ends_quietly(capfd):
    """A command that fails before its figures closes the helper while it may still be importing:
    the helper ends at the end of its input without a word on the (shared) stderr."""
    drawer = FigureDrawer(helper=True)
    process = drawer._process
    drawer.close()
    assert process.returncode is not None  # reaped by close (ended, or killed after HELPER_EXIT_S)
    assert capfd.readouterr().err == ""
    ready = FigureDrawer(helper=True)  # a helper past its imports ends at once when closed
    assert ready.wait_ready(120.0)
    process = ready._process
    ready.close()
    assert process.returncode == 0
