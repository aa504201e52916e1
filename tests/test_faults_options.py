"""Command-line options and resumed configs refused before anything is computed or written."""

import json
import subprocess
import sys

import pytest
from faults_helpers import ROOT, _err


@pytest.mark.parametrize(
    "argv, msg",
    [
        (["--layouts", "0"], "--layouts must be >= 2"),
        (["--validation-layouts", "0"], "--validation-layouts and --workers >= 1"),
        (["--quick", "--bandwidths", "1e-50"], "bandwidth 1e-50 Hz is too small for any image to arrive"),
        (["--quick", "--curves", "nowhere.npz"], "not found"),
    ],
)
def test_eval_options_refused_before_any_computation(tmp_path, capsys, argv, msg):
    from semuav_jax.cli.eval import main

    code, err = _err(capsys, main, [*argv, "--out", str(tmp_path / "o")])
    assert code == 2 and msg in err and err.count("\n") == 1, err
    assert not (tmp_path / "o" / "stages").exists()


@pytest.mark.parametrize(
    "argv, msg",
    [
        (["--bandwidth-range", "none", "5000"], "give either none or numbers"),
        (["--seed", str(2**40)], "seed must be an integer in [0, 2**32)"),
        (["--eval-episodes", "1"], "--eval-episodes must be 0"),
    ],
)
def test_train_options_refused_before_anything_is_written(tmp_path, capsys, argv, msg):
    from semuav_jax.cli.train import main

    code, err = _err(capsys, main, ["--curves", "synthetic", *argv, "--out", str(tmp_path / "r")])
    assert code == 2 and msg in err and err.count("\n") == 1, err
    assert not (tmp_path / "r").exists()


def _stopped_run(tmp_path):
    from semuav_jax.cli.train import load_run_config, parse_args
    from semuav_jax.cli.train_folder import prepare_folder

    out = tmp_path / "r"
    args = parse_args(["--curves", "synthetic", "--total-steps", "40000", "--out", str(out)])
    prepare_folder(args, load_run_config(args)).release()
    return out


@pytest.mark.parametrize(
    "edit, msg",
    [
        (lambda c: c.update(seeds="1"), "seeds must be an integer >= 1"),
        (lambda c: c.update(seeds=-1), "seeds must be an integer >= 1"),
        (lambda c: c.update(segments=0), "segments must be an integer >= 1"),
        (lambda c: c["agent"].update(total_steps=80000), "was edited after the run wrote it"),
    ],
)
def test_resume_revalidates_config_json(tmp_path, capsys, edit, msg):
    from semuav_jax.cli.train import main

    out = _stopped_run(tmp_path)
    cfg = json.loads((out / "config.json").read_text())
    edit(cfg)
    (out / "config.json").write_text(json.dumps(cfg, indent=2))
    code, err = _err(capsys, main, ["--out", str(out), "--resume"])
    assert code == 2 and msg in err and err.count("\n") == 1, err


def test_resume_refuses_a_garbage_metrics_row(tmp_path):
    from semuav_jax.cli.train_folder import UsageError, read_metrics

    (tmp_path / "metrics.csv").write_text("seed,chunk,loss\n0,1,0.5\n0,2,garbage\n")
    with pytest.raises(UsageError, match="metrics.csv line 3 does not parse"):
        read_metrics(tmp_path, 5)
    (tmp_path / "metrics.csv").write_text("seed,chunk,loss\n0,1,0.5\n0,2")  # cut mid-line
    with pytest.raises(UsageError, match="line 3 does not parse"):
        read_metrics(tmp_path, 5)
    (tmp_path / "metrics.csv").write_text("seed,chunk,loss\n0,1,0.5\n0,2,0.25\n")
    assert read_metrics(tmp_path, 1) == [{"seed": 0, "chunk": 1, "loss": 0.5}]


def test_jscc_figure_needs_an_image_path(tmp_path, capsys):
    from semuav_jax.cli.jscc import main

    code, err = _err(capsys, main, ["figure", "--out", str(tmp_path / "j")])
    assert code == 2 and "--out must be a .png, .pdf or .svg file" in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "argv, msg",
    [
        (["--episodes", "1"], "--episodes must be >= 2"),
        (["--B", "1e-50"], "bandwidth 1e-50 Hz is too small for any image to arrive"),
        (["--json", "DIR"], "is a folder, not a file"),
        (["--json", "FILE/sub.json"], "the folder of --json"),
        (["--curves", "nowhere.npz"], "not found"),
    ],
)
def test_baselines_report_checks_options_and_paths_first(tmp_path, argv, msg):
    (tmp_path / "FILE").write_text("x")
    (tmp_path / "DIR").mkdir()
    argv = [str(tmp_path / a) if a.startswith(("DIR", "FILE")) else a for a in argv]
    extra = [] if "--episodes" in argv else ["--episodes", "2"]
    res = subprocess.run(
        [sys.executable, "-m", "semuav_jax.cli.baselines", *argv, *extra],
        capture_output=True,
        text=True,
        check=False,
        cwd=ROOT,
        timeout=120,
    )
    assert res.returncode == 2 and msg in res.stderr and "Traceback" not in res.stderr, res.stderr
