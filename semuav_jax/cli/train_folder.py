"""train.py's run folder (docs/ddqn.md, "Run folder"; docs/reliability.md): the run config read
back and re-validated on ``--resume``, the folder claimed (marker, manifest, lock:
``semuav_jax.runfolder``), and the metrics of a resumed run read back."""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
from pathlib import Path
from typing import TYPE_CHECKING

from semuav_jax.agents.runs import (
    CKPT_FILE,
    CONFIG_FILE,
    METRICS_FILE,
    MODEL_FILE,
    RUN_FILES,
)
from semuav_jax.runfolder import RunFolder

if TYPE_CHECKING:
    from semuav_jax.agents.run_config import RunConfig

INT_COLUMNS = ("seed", "chunk", "env_steps", "episodes")
NONE = "none"  # an option set to none (e.g. --shield-margin none), unlike one not given (None)


class UsageError(Exception):
    """A bad option or run folder: reported as one line, exit code 2."""


def resume_clashes(given: dict, saved: RunConfig) -> list[str]:
    """The options given with --resume (``cli.train.given_options``) whose value differs from the
    saved run's ``RunConfig``, as 'option value (saved x)'."""
    norm = lambda x: json.loads(json.dumps(x))
    clashes = []
    parts = [(f"--env {k}=", v, saved.env.get(k)) for k, v in given["env"].items()]
    parts += [(f"--{k.replace('_', '-')} ", v, getattr(saved.agent, k)) for k, v in given["agent"].items()]
    parts += [
        (f"--{k.replace('_', '-')} ", v, getattr(saved, k)) for k, v in given.items() if k not in ("env", "agent")
    ]
    for name, new, old in parts:  # compared as given: not checked against the other options (they are the saved ones)
        if norm(new) != norm(old):
            clashes.append(f"{name}{new} (saved {old})")
    return clashes


def _config_hash(text: bytes) -> str:
    return hashlib.sha256(text).hexdigest()


def saved_config(args: argparse.Namespace, given: dict) -> RunConfig:
    """The ``RunConfig`` of the run in --out, for --resume: parsed, re-validated as strictly as the
    command line, unedited since the run wrote it, and agreeing with the options ``given``."""
    from semuav_jax.agents.runs import read_config

    out = Path(args.out)
    p = out / CONFIG_FILE
    if not p.is_file():
        raise UsageError(
            f"--resume: no {CONFIG_FILE} in {out}, nothing to resume"
            + ("; the same command without --resume starts it" if (out / ".semuav.json").is_file() else "")
        )
    try:
        saved = read_config(p)
        saved.env_params()
    except (ValueError, FileNotFoundError) as e:
        raise UsageError(f"--resume: {e}") from None
    try:
        marker = json.loads((out / ".semuav.json").read_text())
    except (OSError, ValueError):
        marker = {}
    want = marker.get("config_sha256") if isinstance(marker, dict) else None
    if want and want != _config_hash(p.read_bytes()):
        raise UsageError(
            f"--resume: {p} was edited after the run wrote it; its checkpoint was trained with the "
            "config it had then: restore it, or start a new run (--overwrite or another --out)"
        )
    clashes = resume_clashes(given, saved)
    if args.preset is not None and args.preset != saved.preset:
        clashes.append(f"--preset {args.preset} (saved {saved.preset})")
    if clashes:
        raise UsageError(f"--resume continues the run saved in {out}, whose config differs: {', '.join(clashes)}")
    return saved


def prepare_folder(args: argparse.Namespace, cfg: RunConfig) -> RunFolder:
    """Claim the run folder (locked for this process) and, for a new run, write config.json. A
    folder of ours is refused without --resume / --overwrite unless it holds no checkpoint or model
    yet (a run stopped before its first checkpoint starts again)."""
    out = Path(args.out)
    try:
        folder = RunFolder.claim(out, "train.py run", overwrite=args.overwrite, adopt=RUN_FILES if args.resume else ())
    except ValueError as e:
        raise UsageError(str(e)) from None
    if args.resume:
        return folder
    if any((out / n).exists() for n in (CKPT_FILE, MODEL_FILE)):
        folder.release()
        raise UsageError(f"run folder {out} holds a run; pass --resume to continue it or --overwrite to replace it")
    folder.remove_listed()  # a run stopped before its first checkpoint: nothing of it to keep
    text = json.dumps(cfg.to_dict(), indent=2).encode()
    folder.marker["config_sha256"] = _config_hash(text)
    folder.write(CONFIG_FILE, text)
    return folder


def read_metrics(out: Path, at: int) -> list[dict]:
    """The metrics rows of chunks <= ``at`` (the checkpoint's) from a resumed run's metrics.csv
    (written before the checkpoint: later rows are dropped); UsageError for a row that does not parse."""
    p = out / METRICS_FILE
    if not p.is_file():
        return []
    rows = []
    with open(p, newline="") as f:
        for i, r in enumerate(csv.DictReader(f), start=2):
            try:
                row = {k: int(float(v)) if k in INT_COLUMNS else float(v) for k, v in r.items()}
            except (TypeError, ValueError) as e:
                raise UsageError(
                    f"--resume: {p} line {i} does not parse ({e}); it is rebuilt only by a new run (--overwrite)"
                ) from None
            if row["chunk"] <= at:
                rows.append(row)
    return rows
