"""Choose the hidden and output activations by measurement (issue: "choose by measurement and document").

    python docs/experiments/probes/activation_study.py out/volumes/blazed.exr [--samples 1000000] [--epochs 3]

Trains the 'small' preset with each variant on the same subsample, seed and schedule, and prints the
held-out LogCosh loss (slices 4, 7, 10) and training time as JSON lines.
"""

from __future__ import annotations

import argparse
import json
import tempfile

from gratnet.volume import read_volume
from trainer.train import train
from trainer.train_config import TrainConfig

VARIANTS = (("relu", "clamp"), ("leaky_relu", "clamp"), ("silu", "clamp"), ("relu", "sigmoid"))


def main() -> None:
    """Print one JSON line per variant."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("volume")
    parser.add_argument("--samples", type=int, default=1_000_000)
    parser.add_argument("--epochs", type=int, default=3)
    arguments = parser.parse_args()
    volume = read_volume(arguments.volume)
    for activation, output in VARIANTS:
        config = TrainConfig(
            preset="small",
            activation=activation,
            output_activation=output,
            epochs=arguments.epochs,
            max_train_samples=arguments.samples,
        )
        with tempfile.TemporaryDirectory() as folder:
            _, _, history = train(volume, config, folder, progress=False)
        final = history["epochs"][-1]
        print(
            json.dumps(
                {
                    "volume": arguments.volume,
                    "activation": activation,
                    "output_activation": output,
                    "held_out_loss": final["held_out_loss"],
                    "train_loss": final["train_loss"],
                    "train_seconds": history["train_seconds"],
                }
            ),
            flush=True,
        )


if __name__ == "__main__":
    main()
