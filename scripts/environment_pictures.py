"""The README's opening pictures: materials under the shipped environments, each beside its ground truth.

    python scripts/environment_pictures.py --volume paper-cd=VOLUMES/paper-cd.exr \\
        --volume paper-snake=VOLUMES/paper-snake-s11.exr [--size 320] [--spp 64] [--out docs/images/environments.png]

For each pair (paper-cd under ``sky`` on the CD disc; paper-snake under ``studio`` on the sphere): ``gratnet render
--reference VOLUME`` (the ground-truth volume looked up where the network would run) with the exposure its picture
calls for, then ``gratnet render`` of the network at that exposure, the same view (the material's default camera)
and seed. The four PNGs and their configs go to a temporary folder; the figure (a row per material: ground truth,
network; labelled) is written atomically. The volumes come from ``gratnet groundtruth NAME --sampling simple-max``
(paper-cd: 41 slices; paper-snake: ``--slices 11``, as its model's train_command.json records).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: (material, environment, mesh) per row.
SCENES = (("paper-cd", "sky", "cd"), ("paper-snake", "studio", "sphere"))


def _render(flags: list[str]) -> None:
    from gratnet.cli import main

    status = main(["render", "--quiet", *flags])
    if status != 0:
        raise SystemExit(f"environment_pictures: gratnet render {' '.join(flags)} exited {status}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--volume", action="append", default=[], metavar="MATERIAL=VOLUME.exr")
    parser.add_argument("--size", type=int, default=320)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "images" / "environments.png")
    arguments = parser.parse_args(argv)
    volumes = dict(entry.split("=", 1) for entry in arguments.volume)
    missing = [material for material, _, _ in SCENES if material not in volumes]
    if missing:
        parser.error(f"give --volume for {', '.join(missing)}")

    from PIL import Image, ImageDraw

    from gratnet.atomic import atomic_path

    tiles: list[tuple[Image.Image, str]] = []
    with tempfile.TemporaryDirectory() as folder:
        for material, environment, mesh in SCENES:
            common = ["--material", material, "--mesh", mesh, "--environment", environment, "--size",
                      f"{arguments.size},{arguments.size}", "--spp", str(arguments.spp)]
            truth = Path(folder) / f"{material}_truth.png"
            _render([*common, "--reference", volumes[material], "--out", str(truth)])
            exposure = json.loads(truth.with_suffix(".config.json").read_text())["render"]["exposure"]
            network = Path(folder) / f"{material}_network.png"
            _render([*common, "--exposure", repr(exposure), "--out", str(network)])
            for path, what in ((truth, "ground truth"), (network, "network")):
                tiles.append((Image.open(path).convert("RGB"), f"{material} under {environment}: {what}"))
            print(f"{material} under {environment}: exposure {exposure:g}", file=sys.stderr)
    side = arguments.size
    figure = Image.new("RGB", (2 * side, len(SCENES) * (side + 18)), "white")
    draw = ImageDraw.Draw(figure)
    for index, (tile, label) in enumerate(tiles):
        x, y = (index % 2) * side, (index // 2) * (side + 18)
        figure.paste(tile, (x, y + 18))
        draw.text((x + 4, y + 3), label, fill="black")
    with atomic_path(arguments.out) as temporary:
        figure.save(temporary, format="PNG")
    print(f"wrote {arguments.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
