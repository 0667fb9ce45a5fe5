"""scripts/silence_shipped_models.py re-scores every view a shipped point was evaluated on: the views of its
metrics.config.json, else those its metrics.json records (a point evaluated before configs were saved beside it)."""

from __future__ import annotations

import importlib.util
import json

from tests.helpers import REPO

_SPEC = importlib.util.spec_from_file_location("silence_shipped_models",
                                               REPO / "scripts" / "silence_shipped_models.py")
assert _SPEC is not None and _SPEC.loader is not None
silence = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(silence)

METRICS = {"brdf_slices": [{"slice": "(0°, 0°) 2000 RU", "theta": 0.0, "phi": 0.0, "exposure": 2000.0},
                           {"slice": "(45°, 60°) 5000 RU", "theta": 45.0, "phi": 60.0, "exposure": 5000.0,
                            "extra_view": True},
                           {"slice": "(15°, 200°) 3000 RU", "theta": 15.0, "phi": 200.0, "exposure": 3000.0,
                            "extra_view": True}]}


def test_the_config_names_the_views(tmp_path):
    (tmp_path / "metrics.config.json").write_text(json.dumps({"evaluate": {"views": "1,2,3"}}))
    assert silence.recorded_views(tmp_path, METRICS) == "1,2,3"


def test_without_a_config_the_recorded_extra_views_are_scored_again(tmp_path):
    assert silence.recorded_views(tmp_path, METRICS) == "45,60,5000;15,200,3000"


def test_a_point_with_the_paper_slices_alone_has_no_further_views(tmp_path):
    assert silence.recorded_views(tmp_path, {"brdf_slices": METRICS["brdf_slices"][:1]}) is None
