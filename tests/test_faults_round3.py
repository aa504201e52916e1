"""Bad input and faults, round 3 (docs/reliability.md): values that passed validation, edited or
non-finite models, saved steps of another run, and commands that wrote files nobody named."""

import json
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import TRAIN_TINY
from flax import serialization

from semuav_jax import env as E
from semuav_jax.agents.agent import Agent, evaluate
from semuav_jax.curves import validate_curves
from semuav_jax.params import make_params
from semuav_jax.stats import mean_ci, pm

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def table_env():
    env, p = E.make(E.ENV_ID)
    _, s = env.reset(jax.random.key(0), p)
    return env, p, s


@pytest.mark.parametrize("action", [9, 99, -1, 3.0, None, True, np.array([1, 2])])
def test_step_refuses_an_action_that_is_not_an_integer_in_range(table_env, action):
    env, p, s = table_env
    with pytest.raises(ValueError, match=r"action must be an integer in \[0, 9\)"):
        env.step(jax.random.key(1), s, action, p)


def test_waypoint_action_out_of_range_is_refused_and_traced_ones_are_not_valid(curves):
    env, p = E.make(E.ENV_ID, actions="waypoint", curves=curves)
    _, s = env.reset(jax.random.key(0), p)
    n = env.num_actions
    with pytest.raises(ValueError, match="action must be an integer"):
        env.step(jax.random.key(1), s, -1, p)
    valid = jax.jit(lambda a: env.step(jax.random.key(1), s, a, p)[5]["valid"])
    assert bool(valid(jnp.int32(n - 1))) and not bool(valid(jnp.int32(n))) and not bool(valid(jnp.int32(-1)))


def test_step_refuses_a_state_of_another_n(table_env, curves):
    env, _, s = table_env
    _, p5 = E.make(E.ENV_ID, N=5, curves=curves)
    with pytest.raises(ValueError, match="state has 10 devices but params N = 5"):
        env.step(jax.random.key(1), s, 3, p5)


@pytest.mark.parametrize(
    "kw, msg",
    [
        ({"B": [1e3, 2e3]}, "B must be a scalar"),
        ({"a_max": 1e30}, "a_max must be below"),
        ({"v_max": 1e20}, "v_max must be below"),
        ({"Lx": 1e20}, "Lx must be below"),
        ({"los_a": -1.0}, "los_a must be > 0"),
        ({"los_b": 0.0}, "los_b must be > 0"),
        ({"eta_los": -1.0}, "eta_los must be >= 0"),
        ({"eta_nlos": -3.0}, "eta_nlos must be >= 0"),
        ({"N": 5, "device_pos": np.full((10, 2), 100.0)}, "N = 5 disagrees with device_pos"),
        ({"device_pos": np.array([1.0, 2.0])}, r"device_pos must have shape \(N, 2\)"),
    ],
)
def test_make_params_refuses(curves, kw, msg):
    with pytest.raises(ValueError, match=msg):
        make_params(curves, **kw)


def test_a_max_at_the_bound_still_moves_the_uav(curves):
    """1e18 m/s^2 passes (its square is finite in float32) and the UAV moves: the cap of eq. 3.3 holds."""
    from semuav_jax.kinematics import speed_cap

    p = make_params(curves, a_max=1e18)
    v = speed_cap(jnp.zeros(2), jnp.array([1e18, 0.0]) * p.tau, p)
    np.testing.assert_allclose(np.asarray(v), [p.v_max, 0.0], rtol=1e-6)


def test_curves_below_zero_db_are_refused(curves):
    C = np.array(curves, np.float32)
    C[0, 0] = -0.5
    with pytest.raises(ValueError, match="below 0 dB"):
        validate_curves(C)


@pytest.mark.parametrize("seed", [2**32, 2**64, -1, 1.5, True])
def test_gymnasium_seeds_outside_the_key_range_are_refused(seed):
    from semuav_jax.gym_adapter import SemUAVGymEnv

    with pytest.raises(ValueError, match=r"seed must be an integer in \[0, 2\*\*32\)"):
        SemUAVGymEnv().reset(seed=seed)


def test_one_sample_has_no_interval():
    assert mean_ci([3.0]) == (3.0, None) and pm(None) == "± n/a"
    m, h = mean_ci([1.0, 3.0])
    assert m == 2.0 and h == pytest.approx(12.706 * 1.0, rel=1e-4) and pm(h) == "± 12.71"  # t_0.975(1) * s / sqrt 2


# ----------------------------------------------------------------- agents: edited and non-finite files


@pytest.fixture(scope="module")
def agent():
    return Agent.shipped()


def _edited(tmp_path, agent, run=None, weights=None):
    blob = {
        "format": "semuav-jax agent 1",
        "run": json.dumps(agent.run.to_dict() if run is None else run),
        "weights": jax.tree.map(np.asarray, agent.weights) if weights is None else weights,
    }
    if weights == "missing":
        del blob["weights"]
    path = tmp_path / "a.agent"
    path.write_bytes(serialization.msgpack_serialize(blob))
    return path


def test_agent_load_checks_weights_against_the_config(tmp_path, agent):
    hidden = agent.run.to_dict()
    hidden["agent"]["hidden"] = [8]
    unknown = agent.run.to_dict()
    unknown["agent"]["foo"] = 1
    w = jax.tree.map(np.asarray, agent.weights)
    w["params"]["Dense_0"]["kernel"] = w["params"]["Dense_0"]["kernel"][:, :5]
    cases = [
        ({"run": hidden}, "do not match its config .*Dense_0/kernel"),
        ({"weights": w}, r"Dense_0/kernel \(104, 5\) \(expected \(104, 128\)\)"),
        ({"run": unknown}, "unknown key in its agent config: foo"),
        ({"run": [1]}, "not a semuav-jax agent file"),
        ({"weights": "missing"}, "not a semuav-jax agent file"),
        ({"weights": "a string"}, "do not match its config"),
    ]
    for kw, msg in cases:
        with pytest.raises(ValueError, match=msg) as e:
            Agent.load(_edited(tmp_path, agent, **kw))
        assert "\n" not in str(e.value)


def test_non_finite_agents_are_refused(tmp_path, agent):
    nan = Agent(agent.run, jax.tree.map(lambda x: x * jnp.nan, agent.weights))
    with pytest.raises(ValueError, match="not finite"):
        Agent.load(nan.save(tmp_path / "nan.agent"))
    with pytest.raises(ValueError, match="not finite"):
        evaluate(nan, episodes=2)
    from semuav_jax.agents.runs import shipped_folder

    run = tmp_path / "run"
    run.mkdir()
    (run / "config.json").write_bytes((shipped_folder() / "config.json").read_bytes())
    nets = serialization.msgpack_restore((shipped_folder() / "model.msgpack").read_bytes())
    (run / "model.msgpack").write_bytes(serialization.to_bytes(jax.tree.map(lambda x: x * np.nan, nets)))
    with pytest.raises(ValueError, match="not finite"):
        Agent.from_run(run)


def test_evaluate_refuses_another_n(agent, curves):
    p5 = agent.params.replace(device_pos=agent.params.device_pos[:5], device_img=agent.params.device_img[:5])
    with pytest.raises(ValueError, match="trained with N = 10 devices; params has N = 5"):
        evaluate(agent, p5, episodes=4)


@pytest.mark.slow
def test_evaluation_in_chunks_equals_one_program(agent, monkeypatch):
    from semuav_jax.agents import evaluate as ev
    from semuav_jax.keys import episode_keys

    nets = jax.tree.map(lambda w: w[None], agent.weights)
    keys = episode_keys(0, 4)
    args = (agent.network, nets, agent.config, keys, agent.params, (25e3,))
    whole = ev.seed_metrics(*args)
    monkeypatch.setattr(ev, "MAX_RUNS", 2)  # two chunks of 2 episodes
    chunked = ev.seed_metrics(*args)
    for k in whole:
        np.testing.assert_array_equal(whole[k], chunked[k])


# ----------------------------------------------------------------- saved steps of eval.py


def test_saved_steps_of_another_key_or_unparsable_are_recomputed(tmp_path):
    from semuav_jax.experiments.stages import Stages
    from semuav_jax.runfolder import RunFolder

    folder = RunFolder.claim(tmp_path, "eval.py results")
    notes = []
    first = Stages(folder, {"grid": {"layouts": 20}}, log=lambda m: None)
    assert first("agent evaluated", lambda: {"x": np.arange(3.0)})["x"].tolist() == [0, 1, 2]
    same = Stages(folder, {"grid": {"layouts": 20}}, log=notes.append)
    assert same("agent evaluated", lambda: pytest.fail("recomputed"))["x"].tolist() == [0, 1, 2]
    assert notes == ["agent evaluated (saved before)"]
    other = Stages(folder, {"grid": {"layouts": 24}}, log=notes.append)
    assert other("agent evaluated", lambda: {"x": np.ones(2)})["x"].tolist() == [1, 1]
    assert "was saved for another grid, agent, curves or commit: recomputing it" in notes[1]
    path = tmp_path / "stages" / "agent_evaluated.msgpack"
    path.write_bytes(path.read_bytes()[:7])  # truncated
    assert other("agent evaluated", lambda: {"x": np.zeros(1)})["x"].tolist() == [0]
    assert "does not parse" in notes[3]
    folder.release()


# ----------------------------------------------------------------- command lines


def _err(capsys, main, argv):
    code = main(argv)
    err = capsys.readouterr().err
    return code, err


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


def _jscc_checkpoint(folder, scale=1.0):
    """A checkpoint of a width-4 DeepJSCC at its initial weights times ``scale``, without training."""
    from semuav_jax.jscc.train import (
        TrainConfig,
        init_params,
        make_optimizer,
        save_checkpoint,
    )

    cfg = TrainConfig(steps=2, batch=2, width=4, monotone_weight=0.0, synthetic_fraction=0.0)
    params = jax.tree.map(lambda x: x * scale, init_params(cfg))
    folder.mkdir()
    save_checkpoint(folder, cfg, params, make_optimizer(cfg).init(params), 2, [(2, 0.0, 1.0)])


@pytest.mark.slow
def test_jscc_curves_write_only_the_paths_named(tmp_path, capsys):
    from semuav_jax.cli.jscc import main
    from semuav_jax.curves import load_curves

    _jscc_checkpoint(tmp_path / "ckpt")
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "deepjscc.msgpack").write_text("the user's model")
    assert main(["curves", "--ckpt", str(tmp_path / "ckpt"), "--out", str(tmp_path / "d" / "c.npz")]) == 0
    assert sorted(p.name for p in (tmp_path / "d").iterdir()) == ["c.npz", "deepjscc.msgpack"]
    assert (tmp_path / "d" / "deepjscc.msgpack").read_text() == "the user's model"
    assert load_curves(tmp_path / "d" / "c.npz").meta["model_file"] is None
    assert (
        main(
            [
                "curves",
                "--ckpt",
                str(tmp_path / "ckpt"),
                "--out",
                str(tmp_path / "d" / "c.npz"),
                "--model-out",
                str(tmp_path / "d" / "m.msgpack"),
            ]
        )
        == 0
    )
    assert sorted(p.name for p in (tmp_path / "d").iterdir()) == ["c.npz", "deepjscc.msgpack", "m.msgpack"]


@pytest.mark.slow
def test_jscc_curves_of_a_non_finite_checkpoint_write_nothing(tmp_path, capsys):
    """A NaN model neither replaces the user's deepjscc.msgpack beside --out nor writes curves."""
    from semuav_jax.cli.jscc import main

    _jscc_checkpoint(tmp_path / "ckpt", jnp.nan)
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "deepjscc.msgpack").write_text("the user's model")
    code, err = _err(capsys, main, ["curves", "--ckpt", str(tmp_path / "ckpt"), "--out", str(tmp_path / "d" / "c.npz")])
    assert code == 2 and "not finite" in err
    assert [p.name for p in (tmp_path / "d").iterdir()] == ["deepjscc.msgpack"]
    assert (tmp_path / "d" / "deepjscc.msgpack").read_text() == "the user's model"
    code, err = _err(
        capsys,
        main,
        [
            "curves",
            "--ckpt",
            str(tmp_path / "ckpt"),
            "--out",
            str(tmp_path / "d" / "c.npz"),
            "--model-out",
            str(tmp_path / "d" / "c.npz"),
        ],
    )
    assert code == 2 and "--model-out must be a .msgpack path other than --out" in err


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
        [sys.executable, "-m", "baselines.report", *argv, *extra],
        capture_output=True,
        text=True,
        check=False,
        cwd=ROOT,
        timeout=120,
    )
    assert res.returncode == 2 and msg in res.stderr and "Traceback" not in res.stderr, res.stderr


@pytest.mark.slow
def test_jscc_train_that_diverges_exits_2_and_saves_nothing(tmp_path, capsys, monkeypatch):
    from semuav_jax.cli.jscc import main
    from semuav_jax.jscc import data

    monkeypatch.setattr(
        data, "builtin_train_photos", lambda: [np.random.default_rng(0).random((40, 40, 3), dtype=np.float32)]
    )
    code, err = _err(
        capsys,
        main,
        [
            "train",
            "--out",
            str(tmp_path / "j"),
            "--steps",
            "2",
            "--batch",
            "2",
            "--width",
            "4",
            "--monotone-weight",
            "0",
            "--synthetic-fraction",
            "0",
            "--snr-db",
            "-1000",
        ],
    )
    lines = [ln for ln in err.replace("\r", "\n").splitlines() if "error" in ln]  # beside the progress bar's
    assert code == 2 and len(lines) == 1 and "error: training diverged at step 2" in lines[0], err  # the last step
    assert not (tmp_path / "j" / "checkpoint.msgpack").exists() and not (tmp_path / "j" / ".semuav.lock").exists()


@pytest.mark.slow
def test_train_that_diverges_exits_2_without_a_finished_run(tmp_path):
    out = tmp_path / "r"
    res = subprocess.run(
        [sys.executable, str(ROOT / "train.py"), *TRAIN_TINY, "--lr", "1e38", "--out", str(out)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=900,
        check=False,
    )
    assert res.returncode == 2 and "training diverged (non-finite loss or weights)" in res.stderr, res.stderr
    assert res.stderr.strip().splitlines()[-1].startswith("train.py: error:")
    assert not (out / "model.msgpack").exists() and not (out / "checkpoint.msgpack").exists()


@pytest.mark.slow
def test_ctrl_c_before_the_first_checkpoint_then_resume_finishes(tmp_path):
    """A real SIGINT during the first segment: exit 130, no checkpoint; --resume restarts from chunk 0
    and finishes the run."""
    import signal
    import time

    out = tmp_path / "r"
    p = subprocess.Popen(
        [sys.executable, str(ROOT / "train.py"), *TRAIN_TINY, "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    )
    try:
        deadline = time.time() + 600
        while not (out / "config.json").exists() and time.time() < deadline and p.poll() is None:
            time.sleep(0.2)
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=600)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait(timeout=60)
    assert p.returncode == 130 and "--resume or the same command starts it again" in err, err
    assert not (out / "checkpoint.msgpack").exists()
    res = subprocess.run(
        [sys.executable, str(ROOT / "train.py"), "--out", str(out), "--resume", "--eval-episodes", "0"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=900,
        check=False,
    )
    assert res.returncode == 0 and "no checkpoint yet: starting its run from chunk 0" in res.stdout, res.stderr
    assert (out / "model.msgpack").is_file()
