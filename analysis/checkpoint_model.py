"""A model file from a training checkpoint, or from the average of several: to look at a run stopped before its
end, or at the mean of its late epochs' weights.

    python -m analysis.checkpoint_model RUN/checkpoint.pt VOLUME.exr --out MODEL.npz
    python -m analysis.checkpoint_model RUN/checkpoint-e8.pt RUN/checkpoint-e9.pt RUN/checkpoint.pt VOLUME.exr \
        --out MODEL.npz

`gratnet train` writes RUN/checkpoint.pt after every epoch and the model file only at its end. This builds the
network of the checkpoint's configuration, loads its weights, and writes the model file the trainer's own way
(trainer.train.trained_model_file: encoding, scheme and metadata from the volume it was trained on), so that
`gratnet evaluate`, docs/experiments/probes/flip_maps.py and analysis.encoding_weights can read a stopped run at its
last finished epoch.

Given several checkpoints of one run (copies of checkpoint.pt taken after different epochs; one configuration),
it writes their weights' uniform mean (stochastic weight averaging over epochs, Izmailov et al. 2018, with
torch.optim.swa_utils.AveragedModel): to measure whether the step-to-step jitter Adam leaves in the late epochs'
weights costs fidelity (on paper-scratches it did not: docs/experiments/2026-11-26-scratches-eight-features.md).
The history is the last checkpoint's; the model's training metadata lists the averaged epochs
(``averaged_epochs``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, cast

from gratnet.errors import GratNetError

if TYPE_CHECKING:
    from trainer.model import FunnelMLP, GridNetwork


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("checkpoints", type=Path, nargs="+",
                        help="one `gratnet train` checkpoint.pt, or several of one run to average")
    parser.add_argument("volume", type=Path, help="the ground-truth volume the run was trained on (.exr)")
    parser.add_argument("--out", type=Path, required=True, help="model file to write (.npz)")
    args = parser.parse_args()
    for path in (*args.checkpoints, args.volume):
        if not path.is_file():
            sys.exit(f"checkpoint_model: no such file: {path}")
    from torch.optim.swa_utils import AveragedModel

    from gratnet.modelfile import save_model
    from gratnet.volume import read_volume
    from trainer.train import build_model, read_checkpoint, trained_model_file
    from trainer.train_config import TrainConfig

    try:
        states = [read_checkpoint(path) for path in args.checkpoints]
        configs = [state["config"] for state in states]
        if any(config != configs[0] for config in configs[1:]):
            sys.exit("checkpoint_model: the checkpoints were trained with different configurations; only one run's "
                     "checkpoints can be averaged")
        epochs = [int(state.get("epoch", 0)) for state in states]
        if len(set(epochs)) != len(epochs):
            sys.exit(f"checkpoint_model: the checkpoints repeat an epoch ({epochs}); each must come from another epoch")
        config = TrainConfig(**configs[-1])
        volume = read_volume(args.volume)
        model = build_model(config, config.encoding_for(volume))
        average = AveragedModel(model)
        for state in states:
            model.load_state_dict(state["model"])
            average.update_parameters(model)  # the running uniform mean (the first call copies)
        model = cast("FunnelMLP | GridNetwork", average.module)  # AveragedModel's deep copy of ``model``
    except (GratNetError, OSError, RuntimeError, KeyError, TypeError) as error:
        sys.exit(f"checkpoint_model: cannot rebuild the network of {args.checkpoints[-1]} on {args.volume}: {error}")
    history = dict(states[-1].get("history", {}))
    if len(states) > 1:
        history["averaged_epochs"] = epochs
    save_model(args.out, trained_model_file(model, config, volume, history))
    what = f"mean of epochs {', '.join(map(str, epochs))}" if len(states) > 1 else f"after epoch {epochs[0]}"
    print(f"wrote {args.out} ({what})")


if __name__ == "__main__":
    main()
