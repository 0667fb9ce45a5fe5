"""gratnet.figures.save_figure: opaque figures become RGB PNGs with the same pixels; others keep alpha."""

from __future__ import annotations

import io
from pathlib import Path

import matplotlib
import numpy as np
import pytest
from PIL import Image

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from gratnet.figures import save_figure  # noqa: E402


def _figure(facecolor: str | tuple[float, ...]) -> plt.Figure:
    figure, axes = plt.subplots(figsize=(2.0, 1.5), dpi=50, facecolor=facecolor)
    axes.imshow(np.linspace(0.0, 1.0, 64).reshape(8, 8), cmap="magma")
    axes.set_title("x")
    return figure


def test_opaque_figure_is_rgb_with_matplotlibs_pixels(tmp_path: Path) -> None:
    figure = _figure("white")
    reference = io.BytesIO()
    figure.savefig(reference, format="png", dpi=40)
    save_figure(figure, tmp_path / "f.png", dpi=40)
    plt.close(figure)
    with Image.open(tmp_path / "f.png") as written, Image.open(reference) as expected:
        assert written.mode == "RGB"
        assert expected.mode == "RGBA"
        assert written.size == expected.size == (80, 60)  # dpi honoured
        np.testing.assert_array_equal(np.asarray(written), np.asarray(expected)[..., :3])
    assert [path.name for path in tmp_path.iterdir()] == ["f.png"]  # no temporary left


def test_transparent_figure_keeps_alpha(tmp_path: Path) -> None:
    figure = _figure((1.0, 1.0, 1.0, 0.0))
    save_figure(figure, tmp_path / "t.png")
    plt.close(figure)
    with Image.open(tmp_path / "t.png") as written:
        assert written.mode == "RGBA"
        assert written.getchannel("A").getextrema()[0] == 0


def test_failed_write_leaves_nothing(tmp_path: Path) -> None:
    class Broken:
        def savefig(self, *_: object, **__: object) -> None:
            raise RuntimeError("renderer failed")

    with pytest.raises(RuntimeError):
        save_figure(Broken(), tmp_path / "b.png")
    assert list(tmp_path.iterdir()) == []
