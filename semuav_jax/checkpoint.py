"""Checkpoints of a training run (DDQN ``train.py`` and ``jscc train``): a pytree written atomically
and restored in the structure of a template, so a resumed run continues exactly where it stopped."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import jax
import numpy as np
from flax import serialization

from semuav_jax.io import atomic_write


def save(path: str | os.PathLike, state: Any) -> Path:
    """Write the pytree ``state`` (msgpack) atomically: a kill leaves the previous checkpoint or this one."""
    return atomic_write(path, serialization.to_bytes(state))


def restore(path: str | os.PathLike, template: Any, free: tuple[str, ...] = ()) -> tuple[Any, dict[str, Any]]:
    """``(state, extras)``: the checkpoint at ``path`` in the structure of ``template`` and the
    entries named in ``free`` (top-level keys of a dict checkpoint, restored as saved, None if
    absent); ValueError (one line) if it is unreadable or its arrays are not the template's."""
    try:
        raw = serialization.msgpack_restore(Path(path).read_bytes())
        extras = {k: raw.pop(k, None) for k in free}
        state = serialization.from_state_dict(template, raw)
    except Exception as e:  # noqa: BLE001 - msgpack and flax raise any kind for a file that is not this checkpoint
        raise ValueError(f"{path}: unreadable checkpoint ({type(e).__name__}: {e})") from None
    got, want = jax.tree.leaves(state), jax.tree.leaves(template)
    if jax.tree.structure(state) != jax.tree.structure(template) or any(
        np.shape(a) != np.shape(b) for a, b in zip(got, want)
    ):
        raise ValueError(f"{path}: its arrays do not match the run's config (not this run's checkpoint)")
    return state, extras
