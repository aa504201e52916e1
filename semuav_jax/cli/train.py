"""Train the BS's DDQN from scratch (docs/ddqn.md): ``python train.py`` trains the default agent
(3 seeds vmapped in one program) and compares every seed with the tuned references on 1000 test
layouts at B = 5, 20, 25, 40 kHz; ``--preset paper`` trains the paper's configuration.

The options are derived from the run's config (``agents.run_config.RunConfig``: env overrides,
the agent's ``DDQNConfig``, run options); the config is written whole into the run folder and
replayed on ``--resume`` and by every reader. The training loop is ``cli/train_run.py``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from semuav_jax import distributed
from semuav_jax.cli import interruptible
from semuav_jax.cli.train_folder import NONE, UsageError, prepare_folder, saved_config

if TYPE_CHECKING:
    from semuav_jax.agents.run_config import RunConfig

# the env overrides with an option of their own (any other: --env KEY=VALUE); option -> make_params key
ENV_OPTIONS = {
    "reward_mode": ("reward_mode", {"choices": ("paper", "gain")}, "reward of MODEL.md section 4"),
    "bandwidth": ("B", {"type": float}, "B in Hz when bandwidth_range is none, and of the run's env"),
    "kappa_c": ("kappa_c", {"type": float}, "weight of the PSNR gain in the 'gain' reward"),
    "r_g": ("r_g", {"type": float}, "arrival reward of eq. 4.4"),
}


def _option_type(default: Any) -> dict[str, Any]:
    """argparse type and nargs of a config field from its default value."""
    if isinstance(default, bool):
        return {"type": _boolean}
    if isinstance(default, tuple):
        return {"type": _none_or(type(default[0])), "nargs": "+"}
    if default is None or isinstance(default, float):
        return {"type": _none_or(float)}
    return {"type": type(default)}


def _boolean(text: str) -> bool:
    if text.lower() not in ("true", "false"):
        raise ValueError(text)
    return text.lower() == "true"


def _none_or(kind: Callable[[str], Any]) -> Callable[[str], Any]:
    def parse(text: str) -> Any:
        return NONE if text.lower() == NONE else kind(text)

    parse.__name__ = kind.__name__
    return parse


def _shown(default: Any) -> str:
    values = default if isinstance(default, tuple) else (default,)
    return "none" if default is None else " ".join(f"{x:g}" if isinstance(x, float) else str(x) for x in values)


def _env_pair(text: str) -> tuple[str, Any]:
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE (a make_params override), got {text!r}")
    try:
        return key, json.loads(value)
    except ValueError:
        return key, value


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    from semuav_jax.agents.config import DDQNConfig
    from semuav_jax.agents.run_config import PRESETS, RunConfig

    p = argparse.ArgumentParser(
        description="Train the BS's DDQN from scratch (docs/ddqn.md). Unset options come "
        "from --preset; on --resume, from the run folder."
    )
    p.add_argument(
        "--preset",
        choices=sorted(PRESETS),
        default=None,
        help="default: options (eq. 6.4) with demonstrations, one agent for every B; waypoint: the same with waypoint "
        "actions (eq. 6.2); paper: the paper's configuration",
    )
    env = PRESETS["default"]["env"]
    for name, (key, kind, text) in ENV_OPTIONS.items():
        default = f" (default: {_shown(env[key])})" if key in env else ""
        p.add_argument("--" + name.replace("_", "-"), default=None, help=text + default, **kind)
    p.add_argument(
        "--env",
        type=_env_pair,
        action="append",
        default=None,
        metavar="KEY=VALUE",
        help="any other make_params override of the run's env, e.g. --env K=300 (repeatable)",
    )
    for cls, instance in ((DDQNConfig, RunConfig().agent), (RunConfig, RunConfig())):
        for f in dataclasses.fields(cls):
            if "help" not in f.metadata:
                continue
            default = getattr(instance, f.name)
            kind = {"type": f.metadata["type"]} if "type" in f.metadata else _option_type(default)
            kind |= {"choices": f.metadata["choices"]} if "choices" in f.metadata else {}
            p.add_argument(
                "--" + f.name.replace("_", "-"),
                default=None,
                help=f"{f.metadata['help']} (default: {_shown(default)})",
                **kind,
            )
    p.add_argument(
        "--max-segments",
        type=int,
        default=None,
        help="stop after this many segments in this session (continue later with --resume)",
    )
    p.add_argument("--out", type=str, default=None, help="run folder (default: runs/ddqn_<preset>)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--resume", action="store_true", help="continue the run in --out from its checkpoint")
    g.add_argument("--overwrite", action="store_true", help="delete the contents of an existing --out first")
    distributed.add_options(p)
    args = p.parse_args(argv)
    args.command = " ".join(["python train.py", *(sys.argv[1:] if argv is None else argv)])
    if args.out is None:
        args.out = f"runs/ddqn_{args.preset or 'default'}"
    if args.max_segments is not None and args.max_segments < 1:
        raise UsageError(f"--max-segments must be >= 1, got {args.max_segments}")
    return args


def given_options(args: argparse.Namespace) -> dict:
    """The config values given on the command line: {"env": {...}, "agent": {...}, run option: value}."""
    from semuav_jax.agents.config import DDQNConfig
    from semuav_jax.agents.run_config import RunConfig

    def value(name: str) -> Any:
        v = getattr(args, name)
        if isinstance(v, list) and NONE in v and len(v) > 1:
            raise UsageError(f"--{name.replace('_', '-')}: give either none or numbers, got {' '.join(map(str, v))}")
        return None if v == NONE or v == [NONE] else tuple(v) if isinstance(v, list) else v

    agent = {f.name: value(f.name) for f in dataclasses.fields(DDQNConfig) if getattr(args, f.name) is not None}
    run = {
        f.name: value(f.name)
        for f in dataclasses.fields(RunConfig)
        if "help" in f.metadata and getattr(args, f.name) is not None
    }
    env = dict(args.env or [])
    env |= {key: getattr(args, name) for name, (key, _, _) in ENV_OPTIONS.items() if getattr(args, name) is not None}
    return {"env": env, "agent": agent, **run}


def run_config(args: argparse.Namespace) -> RunConfig:
    """The ``RunConfig`` of a new run: the preset with the options given (an error names the option)."""
    from semuav_jax.agents.config import DDQNConfig
    from semuav_jax.agents.run_config import RunConfig

    try:
        cfg = RunConfig.from_preset(args.preset or "default", command=args.command, **given_options(args))
        cfg.env_params()  # every override and the curves checked before anything is written
    except (ValueError, FileNotFoundError) as e:
        name, _, rest = str(e).partition(" ")
        options = {f.name for cls in (DDQNConfig, RunConfig) for f in dataclasses.fields(cls)}
        raise UsageError(f"--{name.replace('_', '-')} {rest}" if name in options else str(e)) from None
    return cfg


def load_run_config(args: argparse.Namespace) -> RunConfig:
    """The run's config: read back from the run folder on --resume, else built from the options."""
    return saved_config(args, given_options(args)) if args.resume else run_config(args)


def main(argv: list[str] | None = None) -> int:
    return interruptible(
        lambda a: distributed.guarded(_main, a),
        argv,
        "the run folder is consistent: continue with "
        "--resume (before its first checkpoint, --resume or the same command starts it again)",
    )


def _main(argv: list[str] | None = None) -> int:
    from semuav_jax.runfolder import RunFolder

    try:
        args = parse_args(argv)
        distributed.initialize(args)
        cfg = load_run_config(args)
        if distributed.is_main():  # of several processes, process 0 writes the run folder
            folder = prepare_folder(args, cfg)
            distributed.barrier("run folder claimed")
        else:
            distributed.barrier("run folder claimed")
            folder = RunFolder.view(args.out)
    except (UsageError, ValueError, FileNotFoundError, distributed.DistributedError) as e:
        print(f"{Path(sys.argv[0]).name}: error: {e}", file=sys.stderr)
        return 2
    from semuav_jax.cli.train_run import train_run

    try:
        return train_run(cfg, folder, args.resume, args.max_segments)
    finally:
        folder.release()


if __name__ == "__main__":
    sys.exit(main())
