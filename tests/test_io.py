"""hbgear.outputs.io: atomic writers leave either the complete new file or nothing (old file intact)."""

import csv
import json
import math
import os

import numpy as np
import pytest

from hbgear.errors import ConfigError
from hbgear.outputs.io import (
    prepare_out_dir,
    save_figure_atomic,
    write_csv_atomic,
    write_json_atomic,
    write_text_atomic,
)


def leftovers(directory):
    """Temporary files left in `directory`."""
    return [p.name for p in directory.iterdir() if p.name.endswith(".tmp")]


def test_text_roundtrip_and_permissions(tmp_path):
    path = write_text_atomic(tmp_path / "a.txt", "héllo\n")
    assert path.read_text(encoding="utf-8") == "héllo\n"
    umask = os.umask(0)
    os.umask(umask)
    assert os.stat(path).st_mode & 0o777 == 0o666 & ~umask
    write_text_atomic(path, "second")
    assert path.read_text() == "second" and leftovers(tmp_path) == []


def test_json_converts_numpy_and_nonfinite(tmp_path):
    obj = {
        "a": np.float64(1.5),
        "b": np.arange(3),
        "c": (1, float("nan")),
        "d": float("inf"),
        "e": np.int32(7),
        "f": np.bool_(True),
        "g": tmp_path,
        "h": np.array([[1.0, np.nan]]),
    }
    path = write_json_atomic(tmp_path / "x.json", obj)
    back = json.loads(path.read_text())
    assert back == {
        "a": 1.5,
        "b": [0, 1, 2],
        "c": [1, None],
        "d": None,
        "e": 7,
        "f": True,
        "g": str(tmp_path),
        "h": [[1.0, None]],
    }
    assert path.read_text().startswith("{\n  ")


def test_json_unserialisable_writes_nothing(tmp_path):
    target = tmp_path / "x.json"
    target.write_text("old")
    with pytest.raises(TypeError):
        write_json_atomic(target, {"f": object()})
    assert target.read_text() == "old" and leftovers(tmp_path) == []


def test_csv_full_precision_and_bools(tmp_path):
    rows = [(1000.0, 0.1 + 0.2, True, 3), (np.float64(1 / 3), float("nan"), np.bool_(False), 4)]
    path = write_csv_atomic(tmp_path / "t.csv", ["speed_rpm", "x", "stable", "n"], rows)
    lines = list(csv.reader(path.open()))
    assert lines[0] == ["speed_rpm", "x", "stable", "n"]
    assert float(lines[1][1]) == 0.1 + 0.2 and lines[1][2] == "1"
    assert float(lines[2][0]) == 1 / 3 and math.isnan(float(lines[2][1])) and lines[2][2] == "0"


def test_csv_writer_raising_midway_leaves_no_partial_file(tmp_path):
    target = tmp_path / "frc.csv"

    def rows():
        for i in range(1000):
            if i == 500:
                raise RuntimeError("solver blew up")
            yield (i, float(i))

    with pytest.raises(RuntimeError, match="blew up"):
        write_csv_atomic(target, ["i", "x"], rows())
    assert not target.exists() and leftovers(tmp_path) == []

    target.write_text("previous complete file\n")
    with pytest.raises(RuntimeError):
        write_csv_atomic(target, ["i", "x"], rows())
    assert target.read_text() == "previous complete file\n" and leftovers(tmp_path) == []


def test_csv_bad_row_length(tmp_path):
    with pytest.raises(ValueError, match="row 2"):
        write_csv_atomic(tmp_path / "t.csv", ["a", "b"], [(1, 2), (1,)])
    assert list(tmp_path.iterdir()) == []


def test_interrupt_during_rename_leaves_no_temp(tmp_path, monkeypatch):
    def boom(src, dst):
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(KeyboardInterrupt):
        write_text_atomic(tmp_path / "a.txt", "text")
    assert list(tmp_path.iterdir()) == []


def _figure():
    from matplotlib.figure import Figure

    fig = Figure(figsize=(2, 2))
    fig.add_subplot().plot([0, 1], [1, 0])
    return fig


def test_save_figure_png_and_format_from_suffix(tmp_path):
    fig = _figure()
    png = save_figure_atomic(fig, tmp_path / "frc.png", dpi=50)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    svg = save_figure_atomic(fig, tmp_path / "frc.svg")
    assert b"<svg" in svg.read_bytes()[:500]
    assert leftovers(tmp_path) == []


def test_save_figure_failure_midway(tmp_path):
    class Broken:
        def savefig(self, fh, **kwargs):
            fh.write(b"\x89PNG partial")
            raise MemoryError("renderer died")

    with pytest.raises(MemoryError):
        save_figure_atomic(Broken(), tmp_path / "frc.png")
    assert list(tmp_path.iterdir()) == []


def test_prepare_out_dir(tmp_path):
    out = prepare_out_dir(tmp_path / "a" / "b")
    assert out.is_dir()
    assert prepare_out_dir(out) == out  # already there is fine
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(ConfigError) as info:
        prepare_out_dir(blocker / "sub")
    assert info.value.key == "--out"
    with pytest.raises(ConfigError):
        prepare_out_dir(blocker)
