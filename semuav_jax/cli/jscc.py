"""Command line for the DeepJSCC of MODEL.md section 9: train, curves, figure.

``semuav-jscc`` (or ``python -m semuav_jax.cli.jscc``):

semuav-jscc train --out runs/jscc --steps 3600
semuav-jscc curves --ckpt runs/jscc --out semuav_jax/data/psnr_curves.npz \
    --model-out semuav_jax/data/deepjscc.msgpack
semuav-jscc figure --out docs/figures/deepjscc.png
"""

from __future__ import annotations

import argparse
import dataclasses
import sys

from semuav_jax.jscc.config import CHANNELS, TrainConfig


def _train(a: argparse.Namespace) -> None:
    from semuav_jax.jscc import data
    from semuav_jax.jscc.train import check_out, load_config, train

    if a.images and a.cifar10:
        raise ValueError("give at most one of --images and --cifar10")
    if a.minutes is not None and not a.minutes > 0:
        raise ValueError(f"--minutes must be positive, got {a.minutes}")
    check_out(a.out, a.resume, a.overwrite).release()  # checked now; train() claims it for the run
    # every TrainConfig field has the --option of the same name, None when not given
    given = {f.name: getattr(a, f.name) for f in dataclasses.fields(TrainConfig) if getattr(a, f.name) is not None}
    if a.resume:
        cfg, _ = load_config(a.out)
        clash = [
            f"--{k.replace('_', '-')} {v} (saved {getattr(cfg, k)})" for k, v in given.items() if v != getattr(cfg, k)
        ]
        if clash:
            raise ValueError(f"--resume continues the run saved in {a.out}, whose config differs: {', '.join(clash)}")
    else:
        cfg = TrainConfig(**{**given, "init_from": a.init_from or None})
    cfg.validate()  # before the photos are loaded
    if a.images:
        photos = data.folder_photos(a.images)
    elif a.cifar10:
        photos = list(data.cifar10_images(a.cifar10))
    else:
        photos = data.builtin_train_photos()
    _, history = train(cfg, photos, out=a.out, resume=a.resume, minutes=a.minutes, overwrite=a.overwrite)
    if history:
        step, loss, secs = history[-1]
        print(f"step {step}/{cfg.steps}, loss {loss:.5f}, {secs / 60:.1f} min total; checkpoint in {a.out}")


def _curves(a: argparse.Namespace) -> None:
    from semuav_jax.jscc.evaluate import write_curves

    path, C, meta = write_curves(a.ckpt, a.out, model_out=a.model_out)
    print(f"wrote {path}: {C.shape[0]} test images, M = {meta['M']}")
    for frac in ("0", "1/4", "1/2", "1"):
        print(f"  mean PSNR at k = {frac} M: {meta['mean_psnr_db'][frac]:.2f} dB")


def _figure(a: argparse.Namespace) -> None:
    from semuav_jax.jscc.evaluate import make_figure

    print(f"wrote {make_figure(a.out, model=a.model, curves=a.curves)}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="semuav-jscc", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("train", help="train (or resume) the DeepJSCC; checkpoints in --out")
    t.add_argument("--out", required=True, help="checkpoint directory")
    t.add_argument("--steps", type=int, default=None, help="total steps (fixes the lr schedule)")
    t.add_argument("--minutes", type=float, default=None, help="stop (and checkpoint) after this wall-clock time")
    t.add_argument("--resume", action="store_true", help="continue the run saved in --out")
    t.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the checkpoint in --out (its other files stay) instead of refusing",
    )
    t.add_argument("--batch", type=int, default=None)
    t.add_argument("--lr", type=float, default=None)
    t.add_argument("--snr-db", type=float, default=None, help="training AWGN SNR in dB")
    t.add_argument("--width", type=int, default=None, help="conv channels")
    t.add_argument("--seed", type=int, default=None)
    t.add_argument("--init-from", default=None, help="start from the parameters of the run in this directory")
    t.add_argument(
        "--monotone-weight",
        type=float,
        default=None,
        help="weight of the hinge that makes loss(k2) <= loss(k1) for prefixes k1 < k2 (0: plain loss)",
    )
    t.add_argument("--monotone-margin", type=float, default=None, help="margin of that hinge (dB)")
    t.add_argument(
        "--monotone-gap", type=int, default=None, help="half of the hinge's pairs have k2 - k1 uniform in 1..this"
    )
    t.add_argument(
        "--channel",
        choices=CHANNELS,
        default=None,
        help="training channel: AWGN at --snr-db, or noise-free 8-bit I/Q as in the curves",
    )
    t.add_argument(
        "--mask-input", action="store_true", default=None, help="the decoder also sees which latent entries arrived"
    )
    t.add_argument(
        "--synthetic-fraction",
        type=float,
        default=None,
        help="fraction of each batch replaced by synthetic dead-leaves images",
    )
    t.add_argument("--images", default=None, help="train on the images of this folder instead")
    t.add_argument("--cifar10", default=None, help="train on CIFAR-10 python batches in this folder instead")
    t.set_defaults(func=_train)
    c = sub.add_parser("curves", help="evaluate C[i, k] on the held-out test crops and write the curves file")
    c.add_argument("--ckpt", required=True, help="checkpoint directory of `train`")
    c.add_argument("--out", required=True, help="curves .npz to write")
    c.add_argument("--model-out", default=None, help="params .msgpack to write (default: none written)")
    c.set_defaults(func=_curves)
    f = sub.add_parser("figure", help="decoded examples and the PSNR-vs-k curve")
    f.add_argument("--out", required=True, help="png to write")
    f.add_argument("--model", default=None, help="params .msgpack (default: the shipped model)")
    f.add_argument("--curves", default=None, help="curves .npz (default: the shipped curves)")
    f.set_defaults(func=_figure)
    a = p.parse_args(argv)
    try:
        a.func(a)
    except (ValueError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # every checkpoint is written atomically: the folder is consistent
        print("\ninterrupted; continue with --resume" if a.cmd == "train" else "\ninterrupted", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
