"""Issue 42 probe: a trained model with its unseen features silenced afterwards (trainer.unseen.silence_model_file:
the first-layer columns of the encoding's features that vanish at every training sample, the top frequencies'
sines), written beside. At every sample the output is unchanged; between samples the random sinusoids of those
untrained weights are gone. Score both with `gratnet evaluate`.

    python docs/experiments/probes/zero_unseen_posthoc.py MODEL.npz OUT.npz
"""

from __future__ import annotations

import sys

import numpy as np

from gratnet.modelfile import load_model, save_model
from trainer.unseen import silence_model_file


def main() -> None:
    source, target = sys.argv[1], sys.argv[2]
    model = load_model(source)
    before = np.array(model.weights[0])
    columns = silence_model_file(model)
    norms = np.linalg.norm(before[:, columns], axis=0)
    print(f"{source}: zeroed columns {columns}, their norms {np.round(norms, 3).tolist()}")
    save_model(target, model)


if __name__ == "__main__":
    main()
