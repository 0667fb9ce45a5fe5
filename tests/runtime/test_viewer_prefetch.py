"""The viewer warms the other shipped materials' quick programs while it is idle (issue 35): a switch to one of
them then links its programs from Mesa's cache at once, without waiting for a new compile child."""

from __future__ import annotations

import time

from viewer.app import ViewerApp
from viewer.catalog import resolve_material, shipped_materials
from viewer.state import ViewerState


def test_a_switch_to_a_prefetched_material_renders_before_its_own_child_reports(ctx, tmp_path, monkeypatch):
    monkeypatch.setenv("MESA_SHADER_CACHE_DIR", str(tmp_path / "mesa"))  # the children's cache (inherited)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    start = ViewerState(material="paper-cd", mesh="plane", camera_distance=0.2, exposure=40.0)
    app = ViewerApp(ctx, start, size=(16, 16), background=True)
    try:
        following = next(material for material in shipped_materials() if material != "paper-cd")
        wanted = (str(resolve_material(following)), "texture", "surface")
        deadline = time.monotonic() + 180.0
        while wanted not in app.supply.warm and time.monotonic() < deadline:
            app.frame()
            time.sleep(0.05)
        assert wanted in app.supply.warm, f"{following} was not prefetched in 180 s"
        app.switch(material=following)
        for _ in range(20):  # a link or a first draw per frame, from the cache
            app.frame()
            if app.supply.scene_ready(app.state):
                break
        assert app.supply.scene_ready(app.state)
        worker = app.supply.worker
        assert worker is None or ("texture", "surface") not in worker.ready  # linked before its own child said so
        while (app.image is None or app.image.key[0] != following) and time.monotonic() < deadline:
            app.frame()  # the picture, once the quick guess of its view is in (viewer.default_view.GUESS_WAIT_S)
            time.sleep(0.02)
        assert app.image.key[0] == following
    finally:
        app.release()
