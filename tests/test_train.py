"""The train.py command: run folder rules, outputs, resume, clear errors (exit code 2)."""

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest

from semuav_jax.agents.ddqn import DDQNConfig
from semuav_jax.curves import save_curves

ROOT = Path(__file__).resolve().parents[1]
TINY = ["--num-envs", "4", "--steps-per-chunk", "5", "--total-steps", "80", "--learning-starts", "32",
        "--batch-size", "8", "--segments", "2", "--eval-episodes", "4"]


def _train(*args):
    return subprocess.run([sys.executable, str(ROOT / "train.py"), *args], capture_output=True, text=True, cwd=ROOT)


@pytest.fixture(scope="module")
def curves_file(tmp_path_factory, curves):
    return str(save_curves(tmp_path_factory.mktemp("c") / "curves.npz", curves, {"source": "synthetic"}))


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory, curves_file):
    out = tmp_path_factory.mktemp("runs") / "r"
    res = _train("--curves", curves_file, "--out", str(out), "--seeds", "2", *TINY)
    assert res.returncode == 0, res.stderr
    return out


def test_outputs(run_dir):
    for f in ("config.json", "metrics.csv", "learning_curve.png", "checkpoint.msgpack", "model.msgpack", "eval.json"):
        assert (run_dir / f).is_file(), f
    cfg = json.loads((run_dir / "config.json").read_text())
    assert cfg["seeds"] == 2 and cfg["ddqn"]["lr"] == DDQNConfig().lr
    rows = list(csv.DictReader(open(run_dir / "metrics.csv")))
    assert len(rows) == 2 * 4  # 2 seeds x 80 / (4 envs x 5 steps) chunks
    ev = json.loads((run_dir / "eval.json").read_text())
    assert len(ev["seeds"]) == 2 and "ddqn" in ev["seeds"][0]


def test_refuses_existing_folder(run_dir, curves_file):
    res = _train("--curves", curves_file, "--out", str(run_dir), *TINY)
    assert res.returncode == 2
    assert "--resume" in res.stderr and "Traceback" not in res.stderr


def test_interrupted_run_resumes_exactly(run_dir, curves_file, tmp_path):
    """Stop after one of two segments, resume: the final weights equal those of the uninterrupted run."""
    out = tmp_path / "r"
    res = _train("--curves", curves_file, "--out", str(out), "--seeds", "2", *TINY, "--max-segments", "1")
    assert res.returncode == 0, res.stderr
    assert "continue with --resume" in res.stdout and not (out / "model.msgpack").exists()
    res = _train("--out", str(out), "--resume", "--eval-episodes", "0")
    assert res.returncode == 0, res.stderr
    assert "resuming" in res.stdout
    assert (out / "model.msgpack").read_bytes() == (run_dir / "model.msgpack").read_bytes()
    assert len(list(csv.DictReader(open(out / "metrics.csv")))) == 2 * 4


@pytest.mark.parametrize(
    "args, msg",
    [
        (["--seeds", "0"], "--seeds"),
        (["--total-steps", "3"], "less than one chunk"),
        (["--scenario", "moon"], "invalid choice"),
        (["--bandwidth", "-5"], "B must be > 0"),
        (["--curves", "/nonexistent.npz"], "not found"),
    ],
)
def test_bad_options(tmp_path, curves_file, args, msg):
    res = _train("--curves", curves_file, "--out", str(tmp_path / "x"), *args)
    assert res.returncode == 2
    assert msg in res.stderr and "Traceback" not in res.stderr
