"""semuav_jax/render.py and render_mode="rgb_array" of the Gymnasium adapters (docs/env_api.md, "Rendering")."""

import warnings

import gymnasium
import jax
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from matplotlib.figure import Figure
from matplotlib.patches import Circle

from semuav_jax.gym_adapter import SemUAVGymEnv
from semuav_jax.gym_vector import SemUAVVectorEnv
from semuav_jax.render import draw, rgb_frame

K = 12


def test_title_shows_time_and_mean_psnr(params):
    """The clock is t tau of K tau; the PSNR is the mean over devices of phi (eq. 8.1)."""
    ax = Figure().add_subplot()
    m = np.zeros(params.N)
    draw(
        ax,
        params,
        np.asarray(params.device_pos) if params.layout == "fixed" else np.full((params.N, 2), 50.0),
        m,
        np.zeros(params.N, bool),
        np.array([[0.0, 300.0], [5.0, 300.0]]),
        37,
        21.456,
        title="greedy",
    )
    assert ax.get_title() == "greedy\nt =  18.5 s of 125 s   mean PSNR 21.46 dB"
    radius = np.sqrt(105.0**2 - float(params.H) ** 2)  # the range disc of every device (eq. 3.5)
    assert {round(c.radius, 3) for c in ax.patches if isinstance(c, Circle) and c.get_fill()} == {round(radius, 3)}


def test_frames_show_reception_and_the_uav(curves):
    env = SemUAVGymEnv(render_mode="rgb_array", curves=curves, K=K)
    assert env.render() is None  # nothing before the first reset
    env.reset(seed=0)
    first = env.render()
    assert first.shape == (440, 640, 3) and first.dtype == np.uint8
    env.step(8)  # full acceleration: the UAV moves, the trail grows
    moved = env.render()
    assert (moved != first).any()
    state = jax.device_get(env.env_state)
    full = rgb_frame(state.replace(m=np.full_like(state.m, float(env.env_params.M))), env.env_params, env._trail)
    assert (full != moved).any()  # the discs take the colour of the received share
    np.testing.assert_array_equal(rgb_frame(state, env.env_params, env._trail), moved)  # deterministic


def test_vector_frames_equal_single_frames(curves):
    vec = SemUAVVectorEnv(num_envs=2, render_mode="rgb_array", curves=curves, K=K)
    singles = [SemUAVGymEnv(render_mode="rgb_array", curves=curves, K=K) for _ in range(2)]
    vec.reset(seed=4)
    for i, s in enumerate(singles):
        s.reset(seed=4 + i)
    for a in (8, 8, 5):
        vec.step(np.full(2, a))
        for s in singles:
            s.step(a)
    frames = vec.render()
    assert len(frames) == 2
    for f, s in zip(frames, singles):
        np.testing.assert_array_equal(f, s.render())


def test_gymnasium_check_env_with_rendering(curves):
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        check_env(gymnasium.make("SemUAV-v0", render_mode="rgb_array", curves=curves, K=K).unwrapped)


@pytest.mark.parametrize("make", [lambda **kw: SemUAVGymEnv(**kw), lambda **kw: SemUAVVectorEnv(num_envs=2, **kw)])
@pytest.mark.parametrize("mode", ["human", "ansi", "rgb"])
def test_unsupported_render_modes(curves, make, mode):
    with pytest.raises(ValueError, match=f"render_mode must be None or one of \\['rgb_array'\\], got '{mode}'") as err:
        make(render_mode=mode, curves=curves, K=K)
    assert "\n" not in str(err.value)
