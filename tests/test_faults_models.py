"""Edited or non-finite agent files, evaluation of another N or in chunks, and eval.py steps saved for another run."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import serialization

from semuav_jax.agents.agent import Agent, evaluate
from semuav_jax.agents.policy import input_size


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
    n_in = input_size(agent.params, agent.run.agent)
    w["params"]["Dense_0"]["kernel"] = w["params"]["Dense_0"]["kernel"][:, :5]
    cases = [
        ({"run": hidden}, "do not match its config .*Dense_0/kernel"),
        ({"weights": w}, rf"Dense_0/kernel \({n_in}, 5\) \(expected \({n_in}, 128\)\)"),
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
