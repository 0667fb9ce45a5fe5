"""A model file from a training checkpoint: to look at a run stopped before its end.

    python benchmarks/checkpoint_model.py RUN/checkpoint.pt VOLUME.exr --out MODEL.npz

`gratnet train` writes RUN/checkpoint.pt after every epoch and the model file only at its end. This builds the
network of the checkpoint's configuration, loads its weights, and writes the model file the trainer's own way
(trainer.train.trained_model_file: encoding, scheme and metadata from the volume it was trained on), so that
`gratnet evaluate`, benchmarks/flip_maps.py and benchmarks/encoding_weights.py can read a stopped run at its
last finished epoch.
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
    from gratnet.modelfile import save_model
    from gratnet.volume import read_volume
    from trainer.train import build_model, read_checkpoint, trained_model_file
    from trainer.train_config import TrainConfig

    try:
        state = read_checkpoint(args.checkpoint)
        config = TrainConfig(**state["config"])
        volume = read_volume(args.volume)
        model = build_model(config, config.encoding_for(volume))
        model.load_state_dict(state["model"])
    except (GratNetError, OSError, RuntimeError, KeyError, TypeError) as error:
        sys.exit(f"checkpoint_model: cannot rebuild the network of {args.checkpoint} on {args.volume}: {error}")
    save_model(args.out, trained_model_file(model, config, volume, state.get("history", {})))
    epochs = len(state.get("history", {}).get("epochs", []))
    print(f"wrote {args.out} (after epoch {epochs})")


if __name__ == "__main__":
    main()
