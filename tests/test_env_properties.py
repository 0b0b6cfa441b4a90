"""Property-based checks (Hypothesis): any keyword or action gives a working env or a clear ValueError.

Never NaN in what the env returns, never an exception from inside PyBullet or CasADi.
Keywords are checked through :class:`wall_env.config.EnvConfig` (what both envs build
first), so an example costs no PyBullet client or compiled code; actions go to one env
built per test.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import wall_env  # noqa: F401
from wall_env.config import DEFAULT_REWARD_WEIGHTS, RANDOMIZABLE, EnvConfig
from wall_env.tasks import TASKS

EXAMPLES = settings(max_examples=1000, deadline=None, suppress_health_check=[HealthCheck.too_slow])

# anything a user might type, and numbers in and around the valid ranges
_ANYTHING = st.one_of(
    st.none(), st.booleans(), st.integers(-10**9, 10**9), st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-2.0, 2.0), st.floats(0.0, 0.3), st.text(max_size=4), st.lists(st.floats(-1, 1), max_size=3),
    st.complex_numbers(max_magnitude=2.0),
)
_NUMERIC_KEYWORDS = ("k_s", "d_thr", "standoff", "altitude", "duration", "thrust_noise_std", "rate_noise_std",
                     "collision_penalty", "restitution", "max_tracking_error", "control_dt", "physics_substeps",
                     "motor_time_constant", "ground_z", "ceiling_z", "noise", "terminate_on_collision")
_RANGE = st.one_of(_ANYTHING, st.tuples(st.floats(allow_nan=True), st.floats(allow_nan=True)),
                   st.tuples(st.floats(0.0, 10.0), st.floats(0.0, 10.0)))
_KWARGS = st.fixed_dictionaries({}, optional={
    **dict.fromkeys(_NUMERIC_KEYWORDS, _ANYTHING),
    "reward_weights": st.one_of(_ANYTHING, st.dictionaries(
        st.sampled_from([*DEFAULT_REWARD_WEIGHTS, "bogus"]), _ANYTHING, max_size=3)),
    "randomize": st.one_of(_ANYTHING, st.dictionaries(st.sampled_from([*RANDOMIZABLE, "wind"]), _RANGE, max_size=3)),
    "vehicle": st.one_of(st.none(), st.dictionaries(st.sampled_from(["mass", "arm_length", "duct_radius", "wingspan"]),
                                                    _ANYTHING, max_size=2)),
    "task_params": st.one_of(_ANYTHING, st.dictionaries(st.sampled_from(["radius", "period", "bogus"]), _ANYTHING,
                                                        max_size=2)),
    "render_mode": st.one_of(st.none(), st.sampled_from(["rgb_array", "video", ""])),
})


@EXAMPLES
@given(task=st.sampled_from(sorted(TASKS)), kwargs=_KWARGS)
def test_any_keywords_give_a_checked_configuration_or_a_clear_value_error(task, kwargs):
    try:
        config = EnvConfig.from_kwargs(task, **kwargs)
    except ValueError as exc:
        assert str(exc)  # a message, raised by our checks (anything else fails the test)
        return
    numbers = [config.control_dt, config.collision_penalty, config.restitution, config.max_tracking_error,
               config.standoff, config.altitude, config.duration, *config.noise_std, *config.reward_weights.values(),
               *config.truth.theta(), config.vehicle.mass, *[b for r in config.randomize.values() for b in r]]
    assert np.all(np.isfinite(numbers))
    assert config.n_steps >= 1 and config.geometry.p_ref.shape == (config.n_steps + 4 * config.preview_stride + 1, 3)


_ACTION = st.one_of(
    hnp.arrays(np.float64, 4, elements=st.floats(allow_nan=True, allow_infinity=True)),
    hnp.arrays(np.float32, 4, elements=st.floats(-3, 3, width=32)),
    hnp.arrays(np.int64, 4, elements=st.integers(-5, 5)),
    hnp.arrays(np.float64, hnp.array_shapes(min_dims=0, max_dims=3, max_side=5), elements=st.floats(-1, 1)),
    hnp.arrays(np.complex128, 4, elements=st.complex_numbers(max_magnitude=1.0)),
    st.lists(st.one_of(st.floats(-1, 1), st.text(max_size=2), st.none()), max_size=5),
    st.floats(allow_nan=True), st.text(max_size=3), st.none(),
)


def _finite_step(result) -> None:
    obs, reward, terminated, truncated, info = result
    assert np.all(np.isfinite(obs)) and np.all(np.isfinite(reward))
    assert np.all(np.isfinite(info["p_world"])) and np.all(np.isfinite(info["command"]))


_SINGLE: dict[str, gym.Env] = {}


def _single_env() -> gym.Env:
    if "env" not in _SINGLE:
        env = gym.make("WallInspector/WallSweep-v0", disable_env_checker=True)
        env.reset(seed=0)
        _SINGLE["env"] = env
    return _SINGLE["env"]


@EXAMPLES
@given(action=_ACTION)
def test_any_action_gives_a_finite_step_or_a_clear_value_error(action):
    env = _single_env()
    try:
        result = env.step(action)
    except ValueError as exc:
        assert "action" in str(exc)
        return
    _finite_step(result)
    if result[2] or result[3]:
        env.reset()


_VECTOR: dict[str, gym.vector.VectorEnv] = {}


@EXAMPLES
@given(actions=st.one_of(
    hnp.arrays(np.float64, (3, 4), elements=st.floats(allow_nan=True, allow_infinity=True)),
    hnp.arrays(np.float64, (3, 4), elements=st.floats(-2, 2)),
    hnp.arrays(np.float64, hnp.array_shapes(min_dims=0, max_dims=3, max_side=5), elements=st.floats(-1, 1)),
    hnp.arrays(np.complex64, (3, 4), elements=st.complex_numbers(max_magnitude=1.0, width=64)),
    st.lists(st.floats(-1, 1), max_size=12),
))
def test_any_batch_of_actions_gives_a_finite_step_or_a_clear_value_error(actions):
    if "envs" not in _VECTOR:
        _VECTOR["envs"] = gym.make_vec("WallInspector/WallHover-v0", num_envs=3, vectorization_mode="vector_entry_point")
        _VECTOR["envs"].reset(seed=0)
    envs = _VECTOR["envs"]
    try:
        result = envs.step(actions)
    except ValueError as exc:
        assert "action" in str(exc)
        return
    _finite_step(result)
