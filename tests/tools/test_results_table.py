"""analysis.results_table: the paper-datasets table is the shipped metrics, the oracle of the volume each
model was trained on, and the paper's figure, with verdicts that follow from them."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.helpers import REPO

# The paper's table, typed here independently of analysis.results_table: each dataset's own column (paper-snake
# is the corn snake, Elaphe; 0.0318 is the sunbeam snake's column, another dataset).
PAPER = {"paper-blazed": 0.0021, "paper-cd": 0.0178, "paper-snake": 0.0221, "paper-scratches": 0.0123,
         "paper-pits": 0.0878, "paper-corner-cubes": 0.0751, "paper-sunbeam": 0.0318}


def _cells(line: str) -> list[str]:
    return [cell.strip() for cell in line.strip().strip("|").split("|")]


def _paper_table(page: str) -> tuple[dict[str, int], dict[str, list[str]]]:
    """The paper-datasets table: its column indices by header (after the dataset column) and its rows by name."""
    section = page.split("## The paper's datasets against the paper")[1].split("\n## ")[0]
    header = next(line for line in section.splitlines() if line.startswith("| dataset |"))
    column = {name: index for index, name in enumerate(_cells(header)[1:])}
    lines = [line for line in section.splitlines() if line.startswith("| paper-")]
    rows = {cells[0]: cells[1:] for cells in map(_cells, lines)}
    return column, rows


@pytest.fixture(scope="module")
def page(tmp_path_factory) -> str:
    out = tmp_path_factory.mktemp("results") / "results.md"
    subprocess.run([sys.executable, "-m", "analysis.results_table", "--out", str(out)], cwd=REPO, check=True)
    return out.read_text()


def test_every_paper_row_is_its_metrics_with_the_verdicts_that_follow(page):
    column, rows = _paper_table(page)
    names = sorted(path.name for path in (REPO / "assets").glob("paper-*") if (path / "metrics.json").exists())
    assert sorted(rows) == names and len(names) == 8
    for name, cells in rows.items():
        slices = json.loads((REPO / "assets" / name / "metrics.json").read_text())["brdf_slices"]
        normal = next(row for row in slices if row["slice"] == "(0°, 0°) 2000 RU")
        flip = float(cells[column["FLIP (0°, 0°)"]])
        assert flip == pytest.approx(normal["flip"], rel=1e-3)
        verdict = cells[column["beats paper"]]
        if name in PAPER:
            assert cells[column["paper"]] == f"{PAPER[name]:.4g}"
            assert name != "paper-snake" or cells[column["paper's column"]].startswith("corn snake")
            assert verdict == ("**yes**" if normal["flip"] <= PAPER[name] else "no")
        else:
            assert verdict == "—"
        others = [row["flip"] for row in slices if not row.get("extra_view") and row is not normal]
        worst = max(others) / normal["flip"]
        assert cells[column["other 4 slices: worst / (0°, 0°)"]] == f"{worst:.2f}× ({'yes' if worst <= 1.5 else 'no'})"


def test_the_oracle_is_of_the_volume_the_model_was_trained_on(page):
    """A model trained on more w-slices than the CPU here affords (pits 41, scratches 21) takes its oracle from
    the GPU-scored table of the same slice count, never from the 11-slice volume's."""
    column, rows = _paper_table(page)
    for name in ("paper-pits", "paper-scratches"):
        table = json.loads((REPO / "docs" / "data" / f"oracle_{name.removeprefix('paper-')}_slices.json").read_text())
        slices = int(rows[name][column["volume (u*, v* × w)"]].split("×")[-1])
        expected = next(row["brdf_slices"][0]["flip"] for row in table if row["slices"] == slices)
        assert float(rows[name][column["oracle"]]) == pytest.approx(expected, rel=1e-3)


def test_a_slices_table_without_the_trained_count_gives_no_oracle(tmp_path, monkeypatch):
    """No matching slice count: the oracle column says so (—) rather than borrowing another volume's figure."""
    from analysis import results_table
    folder = tmp_path / "paper-pits"
    folder.mkdir()
    (tmp_path / "docs" / "data").mkdir(parents=True)
    table = json.loads((REPO / "docs" / "data" / "oracle_pits_slices.json").read_text())
    (tmp_path / "docs" / "data" / "oracle_pits_slices.json").write_text(
        json.dumps([row for row in table if row["slices"] != 41]))
    monkeypatch.chdir(tmp_path)  # the tables are found relative to the working folder, as the script runs
    assert results_table.paper_oracle(folder, {}, 41) is None
    assert results_table.paper_oracle(folder, {}, 21) == pytest.approx(
        next(row["brdf_slices"][0]["flip"] for row in table if row["slices"] == 21))
    assert results_table.paper_oracle(folder, {"oracle_flip": 0.5}, 41) == 0.5  # its own evaluation first


def test_the_seeds_section_is_the_recorded_seeds_mean_and_spread(page):
    """docs/data/seeds_paper.json (analysis.seed_summary): each dataset's line gives the mean and sample spread
    of its seeds' (0°, 0°) FLIP, recomputed here, and the verdict against the paper's own column."""
    import statistics

    path = REPO / "docs" / "data" / "seeds_paper.json"
    if not path.exists():
        assert "## Seeds" not in page
        return
    section = page.split("## Seeds", 1)[1].split("\n## ", 1)[0]
    for row in json.loads(path.read_text()):
        flips = row["flip_0_0"]
        assert len(flips) == len(row["seeds"]) >= 3  # the rule: a mean over at least three seeds
        line = next(line for line in section.splitlines() if line.startswith(f"| {row['dataset']} |"))
        assert f"{statistics.fmean(flips):.4f} ± {statistics.stdev(flips):.4f}" in line
        verdict = "**yes**" if statistics.fmean(flips) <= PAPER[row["dataset"]] else "no"
        assert f"| {verdict} |" in line


def test_every_row_states_its_models_cost(page):
    """The cost columns are gratnet.cost's figures of each shipped model file, in both material tables."""
    from gratnet.cost import ModelCost

    column, rows = _paper_table(page)
    earlier = page.split("## Earlier materials", 1)[1].split("\n## ", 1)[0]
    header = next(line for line in earlier.splitlines() if line.startswith("| material |"))
    earlier_column = {name: index for index, name in enumerate(_cells(header)[1:])}
    earlier_rows = {cells[0]: cells[1:] for cells in map(_cells, earlier.splitlines()[earlier.splitlines().index(
        header) + 2:]) if cells and cells[0]}
    assert len(earlier_rows) >= 6
    for table_column, table in ((column, rows), (earlier_column, earlier_rows)):
        for name, cells in table.items():
            cost = ModelCost.of_file(REPO / "assets" / name / "model.npz")
            assert cells[table_column["MACs/pixel"]] == f"{cost.macs_per_pixel:,}"
            assert cells[table_column["grid values read"]] == f"{cost.grid_values_read:,}"
            assert float(cells[table_column["MB on disk"]]) == pytest.approx(cost.bytes_on_disk / 1e6, rel=5e-3)
            assert float(cells[table_column["MB on GPU"]]) == pytest.approx(cost.bytes_gpu / 1e6, rel=5e-3)


def test_the_frame_column_is_the_recorded_frame_of_each_material(tmp_path, monkeypatch):
    """With benchmarks/frame_time_1080p.py's record the tables gain its frame per material ('—' where it has
    none); without one, no frame column."""
    from analysis import results_table

    monkeypatch.chdir(tmp_path)  # the record is found relative to the working folder, as the script runs
    assert results_table.frame_times() is None
    assert "frame" not in results_table.cost_header(None)[0]
    record = {"width": 1920, "height": 1080, "machine": {"gl_renderer": "llvmpipe (LLVM 15.0.6, 256 bits)"},
              "models": [{"material": "paper-cd", "ms": 1234.5}, {"material": "cd", "error": "failed"}]}
    (tmp_path / "docs" / "data").mkdir(parents=True)
    (tmp_path / "docs" / "data" / "frame_times_1080p.json").write_text(json.dumps(record))
    record = results_table.frame_times()
    header, separator = results_table.cost_header(record)
    assert header.endswith("| 1080p CD frame (ms, llvmpipe)") and separator.count("---") == header.count("|") + 1
    assert results_table.cost_cells(REPO / "assets" / "paper-cd", record).endswith("| 1,234")
    assert results_table.cost_cells(REPO / "assets" / "cd", record).endswith("| —")  # its measurement failed
    assert results_table.cost_cells(REPO / "assets" / "paper-pits", record).endswith("| —")  # not measured
