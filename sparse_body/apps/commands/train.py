"""`sparse-body train`: its arguments (add_parser) and what it runs (run)."""

from __future__ import annotations

import sys
from pathlib import Path

from .common import between, between_int, mocap_root, positive_int


def _training(method: str):
    """The method's training record (train's choices name only trainable methods)."""
    from ...methods import METHODS

    training = METHODS[method].training
    if training is None:
        raise ValueError(f"{method} is not trained (no learned model)")
    return training


def _trainers(args) -> list[tuple]:
    """(config class, train function, output, report file) for each part the command trains."""
    from ...core.resources import models_dir
    from ...methods import load

    training = _training(args.method)
    names = [part.name for part in training.parts]
    if args.part != "all" and args.part not in names:
        raise ValueError(f"{args.method} has no part {args.part!r}; its parts: all, {', '.join(names)}")
    parts = [part for part in training.parts if args.part in ("all", part.name)]
    config_classes = [load(part.config) for part in parts]
    out = Path(args.out or models_dir() / training.output(lambda: _config(config_classes[0], args)))
    return [
        (config_class, load(part.train), out, part.report(out))
        for part, config_class in zip(parts, config_classes, strict=True)
    ]


def _config(config_class, args):
    """The named training configuration with the command line's overrides: --minutes,
    --steps, --augment, and --set FIELD=VALUE (the value read as the field's type)."""
    from dataclasses import fields

    from ...train.augment import Augmentation

    config = config_class.named(args.config)
    if args.minutes is not None:
        config.minutes = args.minutes
    if args.steps is not None:
        config.steps = args.steps
    if args.augment is not None:
        config.augment = Augmentation.parse(args.augment).spec  # refused here, before any training
    types = {f.name: type(getattr(config, f.name)) for f in fields(config)}
    for item in args.set:
        name, _, value = item.partition("=")
        if name not in types or not value:
            raise ValueError(f"--set {item!r}: expected FIELD=VALUE with FIELD one of {', '.join(types)}")
        kind = types[name]
        try:
            setattr(config, name, value.lower() in ("1", "true", "yes") if kind is bool else kind(value))
        except ValueError:
            raise ValueError(f"--set {item!r}: {name} takes a {kind.__name__}") from None
    return config


def _ablate_augmentation(args, parts) -> None:
    """Each part trained anew (same seed and budget) without augmentation, with its
    configuration's, and with each of those augmentations left out; the validation figures go
    to <model>.augment.json beside the training report, for the model card."""
    import json
    import shutil
    import tempfile

    from ...train.augment import Augmentation
    from ...train.harness import TrainRun, beside

    for config_class, train, out, report_path in parts:
        full = Augmentation.parse(args.augment or config_class.named(args.config).augment)
        specs = ["none", full.spec]  # each spec keeps the full one's splice share
        if len(full.kinds) > 1:
            specs += [full.without(left).spec for left in full.kinds]
        runs = []
        for spec in dict.fromkeys(specs):
            config = _config(config_class, args)
            config.augment = spec
            with tempfile.TemporaryDirectory() as tmp:
                if out.is_dir():  # what an earlier part left there (the predictor trains in the VAE's space)
                    shutil.copytree(out, tmp, dirs_exist_ok=True)
                target = Path(tmp) / out.name if out.suffix == ".onnx" else Path(tmp)
                report = train(config, TrainRun(mocap_root(args), target, args.seed, args.limit))
            runs.append(
                {
                    "augment": spec,
                    "steps": report["steps"],
                    "minutes": report["minutes"],
                    "validation": report["validation"],
                }
            )
            print(f"augment {spec}: {report['validation']}")
        path = beside(report_path, ".augment.json")
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(
            json.dumps({"command": "sparse-body " + " ".join(sys.argv[1:]), "seed": args.seed, "runs": runs}, indent=1)
        )
        print(f"written {path}")


def run(args) -> int:
    import json

    from ...methods import load
    from ...train.harness import TrainRun, beside, use_threads, with_earlier_runs

    parts = _trainers(args)
    if args.ablate_augment:
        use_threads(args.threads)
        _ablate_augmentation(args, parts)
        return 0
    if not (args.card_only or args.render_only):
        use_threads(args.threads)
        configs = [_config(config_class, args) for config_class, *_ in parts]  # errors before training
        for config, (_, train, out, report_path) in zip(configs, parts, strict=True):
            checkpoint = beside(report_path, ".checkpoint.npz")
            earlier = json.loads(report_path.read_text()) if args.resume and report_path.is_file() else None
            report = train(
                config,
                TrainRun(mocap_root(args), out, args.seed, args.limit, checkpoint=checkpoint, resume=args.resume),
            )
            if not args.keep_checkpoint:
                checkpoint.unlink(missing_ok=True)  # the model is exported: nothing left to resume
            report["command"] = "sparse-body " + " ".join(sys.argv[1:])
            report = with_earlier_runs(report, earlier)
            report_path.parent.mkdir(parents=True, exist_ok=True)
            report_path.write_text(json.dumps(report, indent=1))
            print(f"written {out} and {report_path}")
    if not args.no_card:
        mocap = None if args.render_only else mocap_root(args)  # rendering reads only the measured JSON
        card = load(_training(args.method).card)(parts[0][2], mocap, args.limit, not args.render_only)
        print(f"written {card}")
    return 0


def add_parser(sub) -> None:
    from ...methods import METHODS, TRAINABLE

    p = sub.add_parser("train", help="train a learned estimator on the CMU train split (ONNX + model card)")
    trainable = {name: t for name in TRAINABLE if (t := METHODS[name].training) is not None}
    p.add_argument("method", choices=list(trainable), help="the method to train")
    p.add_argument(
        "--config", default="small", help="; ".join(f"{name}: {t.config_help}" for name, t in trainable.items())
    )
    several = {name: [part.name for part in t.parts] for name, t in trainable.items() if len(t.parts) > 1}
    p.add_argument(
        "--part",
        default="all",
        help="of a method with several networks, train all (in order: later ones learn from earlier ones) "
        "or one: " + "; ".join(f"{name}: {', '.join(parts)}" for name, parts in several.items()),
    )
    p.add_argument(
        "--out",
        help="; ".join(f"{name}: {t.out_help}" for name, t in trainable.items()) + " (default: the package's models/)",
    )
    p.add_argument("--minutes", type=between(0.0, 7 * 24 * 60, "minutes"), help="stop training after this long")
    p.add_argument("--steps", type=positive_int, help="stop training after this many steps")
    p.add_argument("--threads", type=between_int(1, 256), default=2, help="torch CPU threads")
    p.add_argument("--seed", type=int, default=0, help="the random seed of the training run")
    p.add_argument("--limit", type=positive_int, help="only the first N clips of each split (smoke runs)")
    p.add_argument("--mocap", help="the CMU folder")
    p.add_argument("--no-card", action="store_true", help="skip the test-split evaluation and model card")
    p.add_argument(
        "--card-only",
        action="store_true",
        help="only rewrite the model card of an existing model: its test-split evaluations again "
        "(<model>.eval.json), then the card from them",
    )
    p.add_argument(
        "--render-only",
        action="store_true",
        help="only rewrite the model card from the measured <model>.eval.json as it is, evaluating nothing",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue an interrupted training from its checkpoint (<model>.checkpoint.npz, written "
        "at every validation: the weights, the optimiser, the learning-rate schedule and the random "
        "draws, so that it goes on as the uninterrupted run would have); --steps counts from the first run",
    )
    p.add_argument(
        "--keep-checkpoint",
        action="store_true",
        help="keep <model>.checkpoint.npz after the export, so that --resume with a larger --steps can "
        "train a finished model further (a schedule set by the step budget follows the new one)",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="override a field of the configuration (repeatable), e.g. --set dropout=0.2",
    )
    p.add_argument(
        "--augment",
        metavar="KINDS",
        help="augmentations of the train clips: mirror,speed,proportions,splice,tilt (any of them; "
        "splice=S and tilt=S for the share of variants), all or none (default: the configuration's)",
    )
    p.add_argument(
        "--ablate-augment",
        action="store_true",
        help="instead of training the model: train without augmentation, with the configuration's "
        "(or --augment's) and with each of its kinds left out (same seed, --minutes each), and "
        "write the validation figures to <model>.augment.json for the model card",
    )
    p.set_defaults(func=run)
