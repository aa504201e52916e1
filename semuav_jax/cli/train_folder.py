"""train.py's run folder (docs/ddqn.md, "Run folder"; docs/reliability.md): the run config read
back and re-validated on ``--resume``, the folder claimed (marker, manifest, lock:
``semuav_jax.runfolder``), and the metrics of a resumed run read back."""

from __future__ import annotations

import csv
import hashlib
import json
import math
from pathlib import Path

from semuav_jax.agents.runs import (
    CKPT_FILE,
    CONFIG_FILE,
    METRICS_FILE,
    MODEL_FILE,
    RUN_FILES,
    ddqn_config,
)
from semuav_jax.runfolder import RunFolder

SCENARIO = {"scenario": "random", "reward_mode": "gain", "bandwidth": 25e3, "kappa_c": 10.0, "r_g": 0.0}
RUN_OPTIONS = {
    "seeds": (3, "independent agents trained in one program"),
    "seed": (0, "base random seed"),
    "segments": (50, "host-level segments (progress + checkpoint each)"),
}
INT_COLUMNS = ("seed", "chunk", "env_steps", "episodes")
NONE = "none"  # an option set to none (e.g. --shield-margin none), unlike one not given (None)
SEED_RANGE = 2**32  # jax.random.PRNGKey aliases seeds modulo 2**32


class UsageError(Exception):
    """A bad option or run folder: reported as one line, exit code 2."""


def check_run(cfg: dict, where: str) -> None:
    """UsageError (one line) unless the run description ``cfg`` (built from the options, or read from
    config.json at ``where``) holds values the command line would accept."""

    def bad(name, v, want):
        raise UsageError(f"{where}{': ' if where else ''}{name} must be {want}, got {v!r}")

    for name in ("seeds", "segments"):
        v = cfg.get(name)
        if not isinstance(v, int) or isinstance(v, bool) or v < 1:
            bad(name, v, "an integer >= 1")
    if not isinstance(cfg.get("seed"), int) or isinstance(cfg["seed"], bool) or not 0 <= cfg["seed"] < SEED_RANGE:
        bad("seed", cfg.get("seed"), "an integer in [0, 2**32) (random keys alias seeds modulo 2**32)")
    if cfg.get("scenario") not in ("fixed", "random"):
        bad("scenario", cfg.get("scenario"), "'fixed' or 'random'")
    if cfg.get("reward_mode") not in ("paper", "gain"):
        bad("reward_mode", cfg.get("reward_mode"), "'paper' or 'gain'")
    for name, positive in (("bandwidth", True), ("kappa_c", False), ("r_g", False)):
        v = cfg.get(name)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or (positive and v <= 0):
            bad(name, v, "a finite number" + (" > 0" if positive else ""))
    if cfg.get("curves") is not None and not isinstance(cfg["curves"], str):
        bad("curves", cfg["curves"], "a file name, 'synthetic' or null")
    try:
        ddqn_config(cfg, where or "the options")
    except ValueError as e:
        raise UsageError(str(e)) from None


def resume_clashes(args, saved: dict) -> list[str]:
    """The options given with --resume whose value differs from the saved run's, as 'option value (saved x)'."""
    import dataclasses

    from semuav_jax.agents.ddqn import DDQNConfig

    ddqn = {f.name for f in dataclasses.fields(DDQNConfig)}
    norm = lambda x: json.loads(json.dumps(x))
    clashes = []
    for name in (*ddqn, *SCENARIO, *RUN_OPTIONS, "curves"):
        new = getattr(args, name)  # compared as given: not checked against the other options (they are the saved ones)
        if new is None:
            continue
        new = None if new == NONE or new == [NONE] else new
        old = saved["ddqn"].get(name) if name in ddqn else saved.get(name)
        if norm(new) != norm(old):
            clashes.append(f"--{name.replace('_', '-')} {new} (saved {old})")
    if args.preset != "default" and args.preset != saved.get("preset"):
        clashes.append(f"--preset {args.preset} (saved {saved.get('preset')})")
    return clashes


def _config_hash(text: bytes) -> str:
    return hashlib.sha256(text).hexdigest()


def saved_config(args) -> dict:
    """The config.json of the run in --out, for --resume: parsed, re-validated as strictly as the
    command line, unedited since the run wrote it, and agreeing with the options given."""
    out = Path(args.out)
    p = out / CONFIG_FILE
    if not p.is_file():
        raise UsageError(
            f"--resume: no {CONFIG_FILE} in {out}, nothing to resume"
            + ("; the same command without --resume starts it" if (out / ".semuav.json").is_file() else "")
        )
    try:
        saved = json.loads(p.read_text())
    except ValueError:
        raise UsageError(f"--resume: {p} is not a train.py run config") from None
    needed = ("ddqn", "scenario", "reward_mode", "bandwidth", "kappa_c", *RUN_OPTIONS)
    missing = [k for k in needed if not isinstance(saved, dict) or k not in saved]
    if missing:
        raise UsageError(f"--resume: {p} is not a train.py run config (no {', '.join(map(repr, missing))})")
    check_run(saved, f"--resume: {p}")
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
    clashes = resume_clashes(args, saved)
    if clashes:
        raise UsageError(f"--resume continues the run saved in {out}, whose config differs: {', '.join(clashes)}")
    return saved


def prepare_folder(args, cfg: dict) -> RunFolder:
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
    text = json.dumps(cfg, indent=2).encode()
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
