"""A model file from a training checkpoint: to look at a run stopped before its end.

    python benchmarks/checkpoint_model.py RUN/checkpoint.pt VOLUME.exr --out MODEL.npz

`gratnet train` writes RUN/checkpoint.pt after every epoch and the model file only at its end. This builds the
network of the checkpoint's configuration, loads its weights, and writes the model file the way the trainer does
(encoding and scheme from the volume it was trained on), so that `gratnet evaluate`, benchmarks/flip_maps.py
and benchmarks/encoding_weights.py can read a stopped run at its last finished epoch.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from gratnet.errors import GratNetError


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("checkpoint", type=Path, help="a `gratnet train` checkpoint.pt")
    parser.add_argument("volume", type=Path, help="the ground-truth volume the run was trained on (.exr)")
    parser.add_argument("--out", type=Path, required=True, help="model file to write (.npz)")
    args = parser.parse_args()
    for path in (args.checkpoint, args.volume):
        if not path.is_file():
            sys.exit(f"checkpoint_model: no such file: {path}")
    import torch

    from gratnet.modelfile import save_model
    from gratnet.volume import read_volume
    from trainer.train import build_model
    from trainer.train_config import TrainConfig

    try:
        state = torch.load(args.checkpoint, map_location="cpu", weights_only=False)
        config = TrainConfig(**state["config"])
        volume = read_volume(args.volume)
        encoding = config.encoding_for(volume)
        model = build_model(config, encoding)
        model.load_state_dict(state["model"])
    except (GratNetError, OSError, RuntimeError, KeyError, TypeError) as error:
        sys.exit(f"checkpoint_model: cannot rebuild the network of {args.checkpoint} on {args.volume}: {error}")
    save_model(args.out, model.to_model_file(encoding=encoding, range=config.range_spec(),
                                             scheme=volume.metadata["scheme"], metadata={}))
    epochs = len(state.get("history", {}).get("epochs", []))
    print(f"wrote {args.out} (after epoch {epochs})")


if __name__ == "__main__":
    main()
