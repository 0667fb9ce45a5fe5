"""analysis.lut_baseline: the plot of earlier runs (one or several materials) and its argument checks."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from analysis.lut_baseline import main


def _rows(path: Path, material: str, scale: float) -> Path:
    rows = [{"material": material, "what": what, "mb": mb, "ms_per_frame": ms * scale, "flip_mean": flip,
             "flip_slices": [flip] * 5, "frame": "1920x1080", "renderer": "test"}
            for what, mb, ms, flip in (("network", 4.0, 20000.0, 0.02), ("look-up 1001² × 11", 66.0, 150.0, 0.005))]
    path.write_text(json.dumps(rows), encoding="utf-8")
    return path


def test_plot_only_draws_several_materials_in_one_figure(tmp_path):
    first, second = _rows(tmp_path / "a.json", "paper-cd", 1.0), _rows(tmp_path / "b.json", "paper-pits", 2.0)
    out = tmp_path / "plot.png"
    assert main(["--plot-only", "--json", str(first), str(second), "--figure", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(tmp_path.glob(".*tmp*"))  # written through a temporary, nothing left beside it


@pytest.mark.parametrize("argv, message", [
    (["--plot-only", "--json", "MISSING.json", "--figure", "p.png"], "no such file"),
    (["paper-cd", "v.exr", "--plot-only", "--json", "a.json", "--figure", "p.png"], "no material or volume"),
    (["--figure", "p.png"], "a material and its volume"),
    (["paper-cd", "v.exr", "--json", "a.json", "b.json"], "one file when measuring"),
])
def test_bad_arguments_are_refused_in_one_line_before_any_work(tmp_path, monkeypatch, capsys, argv, message):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as stopped:
        main(argv)
    assert stopped.value.code == 2
    assert message in capsys.readouterr().err
