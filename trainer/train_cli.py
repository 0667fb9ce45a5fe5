"""``gratnet train VOLUME.exr --out DIR`` and ``gratnet evaluate MODEL.npz --out DIR``."""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import Any

from gratnet.config import add_arguments, add_quiet_flag, from_arguments, save_config
from gratnet.errors import GratNetError


def _add_evaluation_inputs(parser: argparse.ArgumentParser) -> None:
    from trainer.evaluate import EvaluateConfig
    from trainer.heightfile import LoadOptions

    parser.add_argument(
        "--heightfield",
        metavar="SPEC",
        help="height field for ground-truth BRDF slices (default: the volume's recorded generator)",
    )
    add_arguments(parser, EvaluateConfig)
    add_arguments(parser, LoadOptions)
    add_quiet_flag(parser)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``train`` and ``evaluate``."""
    from trainer.train_config import TrainConfig, mark_recipe_flags

    train = subparsers.add_parser(
        "train",
        help="train a funnel MLP on a ground-truth volume and evaluate it",
        description="Train the funnel MLP on a volume (LogCosh, Adam, cosine schedule), write DIR/model.npz, "
        "DIR/checkpoint.pt, DIR/history.json, then a report (metrics.json, report.md, PNG figures).",
        epilog="typical use:\n  gratnet train blazed.exr --out out/blazed --epochs 6",
    )
    train.add_argument("volume", metavar="VOLUME.exr", help="ground-truth volume from gratnet groundtruth")
    train.add_argument("--out", required=True, metavar="DIR", help="output folder")
    train.add_argument("--resume", action="store_true", help="continue from DIR/checkpoint.pt")
    train.add_argument("--no-evaluate", action="store_true", help="skip the evaluation report")
    mark_recipe_flags(add_arguments(train, TrainConfig))  # --preset fast's options: explicit values win
    _add_evaluation_inputs(train)
    train.set_defaults(handler=run_train)

    evaluate = subparsers.add_parser(
        "evaluate",
        help="evaluate a model file on held-out volume slices and the paper's BRDF slices",
        description="Write DIR/metrics.json, DIR/report.md and PNG figures (ground truth | network | FLIP).",
        epilog="typical use:\n  gratnet evaluate assets/blazed/model.npz --volume blazed.exr --out out/report",
    )
    evaluate.add_argument("model", metavar="MODEL.npz", help="model file from gratnet train")
    evaluate.add_argument("--out", required=True, metavar="DIR", help="report folder")
    evaluate.add_argument("--volume", metavar="VOLUME.exr", help="ground-truth volume for the volume-slice metrics")
    evaluate.add_argument("--volume-slices", default=None,
                          help="volume slices to evaluate, comma-separated indices (default: the slices the model's "
                          "training held out: its --test-slices under --split slices, none under --split all or "
                          "random, whose every slice was trained on; 4,7,10 when the model does not say)")
    _add_evaluation_inputs(evaluate)
    evaluate.set_defaults(handler=run_evaluate)


def ground_truth_inputs(arguments: argparse.Namespace, volume_metadata: dict[str, Any]) -> tuple[Any, Any]:
    """Height field and optics for ground-truth BRDF slices, or (None, None) with a message."""
    from trainer.fourier import OpticsConfig
    from trainer.heightfile import LoadOptions
    from trainer.loaders import load_heightfield

    spec = arguments.heightfield or volume_metadata.get("source", "")
    if not spec or not (arguments.heightfield or str(spec).startswith(("generator:", "dataset:"))):
        print(
            "gratnet: no --heightfield and the volume was not made by a built-in generator: skipping BRDF slices",
            file=sys.stderr,
        )
        return None, None
    field = load_heightfield(spec, from_arguments(LoadOptions, arguments))
    return field, OpticsConfig.from_volume_metadata(volume_metadata)


def _slice_list(text: str, what: str) -> list[int]:
    try:
        slices = sorted({int(part) for part in text.split(",") if part.strip()})
    except ValueError:
        raise GratNetError(f"{what} must be comma-separated integers, got {text!r}") from None
    if not slices:
        raise GratNetError(f"{what} names no slice, got {text!r}")
    return slices


def _check_before_work(arguments: argparse.Namespace, evaluating: bool) -> None:
    """The output folder and the cache folder, before any loading or training (the evaluation's numbers are
    checked by EvaluateConfig)."""
    from gratnet.atomic import check_output_folder

    check_output_folder(arguments.out)
    if evaluating and arguments.brdf_slices:
        check_output_folder(arguments.cache_dir, "--cache-dir")


#: The slice scored after each epoch by --epoch-flip-size: the paper's headline view, (0°, 0°) at 2000 RU.
EPOCH_FLIP_SLICE = (0.0, 0.0, 2000.0)


def _epoch_flip(arguments: argparse.Namespace, config: Any, volume_metadata: dict[str, Any]) -> Any:
    """A per-epoch callback: mean FLIP of the network's (0°, 0°) 2000 RU slice at a low size against the
    exact ground truth (computed once, cached); None with a message when there is no height field."""
    from trainer.brdfslice import SliceConfig
    from trainer.evaluate import ground_truth_brdf_slice, network_brdf_slice
    from trainer.metrics import flip

    field, optics = ground_truth_inputs(arguments, volume_metadata)
    if field is None:
        return None
    theta, phi, exposure = EPOCH_FLIP_SLICE
    slice_config = SliceConfig(theta, phi, size=config.epoch_flip_size, exposure=exposure, ior=arguments.ior)
    reference = ground_truth_brdf_slice(field, optics, slice_config, arguments.cache_dir, not arguments.quiet)

    def score(model_file: Any) -> dict[str, Any]:
        return {"slice_flip": flip(reference, network_brdf_slice(model_file, slice_config))[0]}

    return score


def interrupted_state(checkpoint: Path, epochs: int) -> str:
    """What an interrupted training leaves, in words: the checkpoint's epoch and how to continue from it."""
    from trainer.train import read_checkpoint

    if not checkpoint.is_file():
        return "no epoch was finished, so there is no checkpoint to resume from"
    try:
        done = int(read_checkpoint(checkpoint)["epoch"])
    except (GratNetError, KeyError, TypeError, ValueError):
        return f"{checkpoint} is unreadable; start afresh without --resume"
    return (f"{checkpoint} holds epoch {done} of {epochs}: the same command with --resume continues from there, "
            f"as the uninterrupted run would have")


def with_slope_covariance(arguments: argparse.Namespace, volume_metadata: dict[str, Any]) -> None:
    """Fill in the volume's ``slope_covariance`` (Smith's shadowing, gratnet.shadowing) where a volume made before
    the ground truth recorded it lacks it: from ``--heightfield`` or the height field its ``source`` names. Where
    that cannot be loaded, say so once: the model will render unshadowed."""
    from gratnet.shadowing import METADATA_KEY
    from trainer.heightfile import LoadOptions
    from trainer.loaders import load_heightfield

    if volume_metadata.get(METADATA_KEY) is not None:
        return
    spec = arguments.heightfield or str(volume_metadata.get("source", ""))
    try:
        field = load_heightfield(spec, from_arguments(LoadOptions, arguments))
    except GratNetError as error:
        print(f"gratnet train: the volume records no slope covariance and its height field cannot be loaded "
              f"({error}); the model will render unshadowed", file=sys.stderr)
        return
    volume_metadata[METADATA_KEY] = list(field.slope_covariance())


def run_train(arguments: argparse.Namespace) -> int:
    """Train, save, evaluate."""
    from gratnet.volume import read_volume
    from trainer.evaluate import EvaluateConfig, evaluate_model
    from trainer.train import train
    from trainer.train_config import config_from_arguments

    config = config_from_arguments(arguments)  # a recipe preset's options filled in where not given
    evaluate_config = dataclasses.replace(from_arguments(EvaluateConfig, arguments), progress=not arguments.quiet)
    _check_before_work(arguments, evaluating=not arguments.no_evaluate)
    checkpoint = Path(arguments.out) / "checkpoint.pt"
    if arguments.resume and not checkpoint.is_file():  # training afresh would silently ignore --resume
        raise GratNetError(f"--resume: there is no {checkpoint} to continue from; leave out --resume to start afresh")
    held_out = config.held_out_slices() if config.split == "slices" else []
    volume = read_volume(arguments.volume)
    with_slope_covariance(arguments, volume.metadata)
    out = Path(arguments.out)
    per_epoch = _epoch_flip(arguments, config, volume.metadata) if config.epoch_flip_size else None
    try:
        model, model_file, history = train(volume, config, out, resume=arguments.resume,
                                           progress=not arguments.quiet, per_epoch=per_epoch)
    except KeyboardInterrupt:
        print(f"gratnet train: interrupted; {interrupted_state(checkpoint, config.epochs)}", file=sys.stderr)
        return 130
    save_config(out / "model.npz", train=config, volume=arguments.volume)
    print(
        f"wrote {out / 'model.npz'}: {model.parameter_count} parameters, layers {model.sizes}, "
        f"{history['train_seconds']:.0f} s of training"
    )
    if not arguments.no_evaluate:
        field, optics = (
            ground_truth_inputs(arguments, volume.metadata) if evaluate_config.brdf_slices else (None, None)
        )
        evaluate_model(
            model_file,
            out,
            evaluate_config,
            volume=volume,
            field=field,
            optics=optics,
            volume_slices=held_out,
            extra={"training": {k: v for k, v in history.items() if k != "epochs"}},
            history=history,
            model_path=out / "model.npz",
        )
        print(f"wrote {out / 'report.md'}")
    return 0


def _read_history(path: Path) -> dict[str, Any] | None:
    """The training history beside a model, for its curves; None when absent or unreadable (it is optional)."""
    import json

    try:
        history = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return history if isinstance(history, dict) and isinstance(history.get("epochs"), list) else None


def held_out_slices(metadata: dict) -> list[int]:
    """The volume slices a model's training held out (its metadata's training config); [4, 7, 10] when unknown."""
    config = metadata.get("training", {}).get("config")
    if not isinstance(config, dict) or "split" not in config:
        return [4, 7, 10]
    if config["split"] != "slices":
        return []  # every slice was trained on: scoring one would not test anything
    return _slice_list(str(config.get("test_slices", "4,7,10")), "the model's test_slices")


def run_evaluate(arguments: argparse.Namespace) -> int:
    """Evaluate an existing model file."""
    from gratnet.modelfile import load_model
    from gratnet.volume import read_volume
    from trainer.evaluate import EvaluateConfig, evaluate_model

    evaluate_config = dataclasses.replace(from_arguments(EvaluateConfig, arguments), progress=not arguments.quiet)
    _check_before_work(arguments, evaluating=True)
    explicit = bool(arguments.volume) and arguments.volume_slices is not None
    slices = _slice_list(arguments.volume_slices, "--volume-slices") if explicit else []
    model = load_model(arguments.model)
    if arguments.volume and not explicit:
        slices = held_out_slices(model.metadata)
    volume = read_volume(arguments.volume) if arguments.volume else None
    metadata = volume.metadata if volume is not None else model.metadata.get("volume", {})
    field, optics = ground_truth_inputs(arguments, metadata) if evaluate_config.brdf_slices else (None, None)
    history_path = Path(arguments.model).with_name("history.json")  # the training's, beside a trained model
    history = _read_history(history_path)
    evaluate_model(
        model, arguments.out, evaluate_config, volume=volume, field=field, optics=optics, volume_slices=slices,
        history=history, model_path=arguments.model,
    )
    save_config(
        Path(arguments.out) / "metrics.json",
        evaluate=evaluate_config,
        model=arguments.model,
        volume=arguments.volume,
        heightfield=arguments.heightfield,
    )
    print(f"wrote {Path(arguments.out) / 'report.md'}")
    return 0
