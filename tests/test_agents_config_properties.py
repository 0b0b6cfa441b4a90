"""Property: any ``--set KEY=VALUE`` gives a valid configuration or a ``ValueError`` that
names the entry; never another exception (which ``train`` would show as a traceback)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents.config import _BASE, apply_overrides, default_config
from agents.train import planned_timesteps, policy_description

CONFIG = default_config("WallHover")
KEYS = sorted([key for key, value in _BASE.items() if not isinstance(value, dict)]
              + [f"{section}.{key}" for section, value in _BASE.items() if isinstance(value, dict)
                 for key in value]
              + ["bogus", "ppo.bogus", "eval.bogus", "env_kwargs", "ppo", "residual_base_kwargs", "residual_base_kwargs.pid"])

scalars = st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6), st.floats(allow_nan=True),
                    st.text(max_size=8))
yaml_values = st.one_of(
    scalars.map(lambda v: "null" if v is None else str(v).lower() if isinstance(v, bool) else str(v)),
    st.lists(scalars, max_size=5).map(lambda items: "[" + ", ".join(map(repr, items)) + "]"),
    st.dictionaries(st.text(max_size=5), scalars, max_size=3).map(repr),
    st.text(max_size=20),  # anything at all, YAML or not
)


@settings(max_examples=1000, deadline=None)
@given(key=st.sampled_from(KEYS), value=yaml_values)
def test_any_override_is_valid_or_a_clear_value_error(key, value):
    try:
        config = apply_overrides(CONFIG, [f"{key}={value}"])
    except ValueError as exc:
        assert str(exc)  # a message, not an empty error
        return
    assert isinstance(config["timesteps"], int) and config["timesteps"] >= 1
    assert isinstance(config["ppo"]["n_steps"], int) and config["ppo"]["n_steps"] >= 1
    assert len(config["residual_scale"]) == 4
    assert policy_description(config)["env_id"] == "WallInspector/WallHover-v0"  # what train does next
    try:
        assert planned_timesteps(config) <= config["timesteps"]
    except ValueError:  # fewer steps than one rollout: refused with a message
        pass


@pytest.mark.parametrize("override", ["residual_scale=null", "residual_scale={a: 1}", "eval=3", "ppo.gamma=.nan",
                                      "randomize_ranges=[1, 2]", "timesteps=1e6"])
def test_awkward_overrides_found_by_the_property_are_value_errors(override):
    with pytest.raises(ValueError):
        apply_overrides(CONFIG, [override])
