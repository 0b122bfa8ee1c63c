"""cgda_jax.checks: eager finite checks and checkify-based checks for jitted code."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cgda_jax.checks import (
    FLOAT32_MAX,
    check_finite,
    check_float32,
    checked,
    checkified,
    require_finite,
)
from cgda_jax.distance import dtw


def test_check_finite_names_input_index_and_value():
    check_finite(np.ones((2, 3)), "a")
    check_finite(np.arange(3), "ints")  # integers are always finite
    with pytest.raises(ValueError, match=r"^f: input 'a' has a non-finite value nan "
                       r"at index \[1, 2\]$"):
        check_finite(np.array([[0.0, 1, 2], [3, 4, np.nan]]), "a", where="f")
    check_finite(np.array([1e39]), "wide")  # finite float64: fine without a limit
    with pytest.raises(ValueError, match=r"input 'wide' has a value 1e\+39 beyond "
                       r"\+/-3\.403e\+38 \(float32 overflows\) at index \[0\]"):
        check_float32(np.array([1e39]), "wide")
    check_float32(np.array([FLOAT32_MAX, -FLOAT32_MAX]), "edge")
    # tracers are not checked (no host sync); they are left to the NaN rule
    jax.jit(lambda v: check_finite(v, "v") or v)(jnp.array([jnp.nan]))


def test_checkified_in_a_jitted_scan_throws_once_naming_the_pytree_leaf():
    def step(carry, xs):
        return carry + jnp.sum(xs["a"]) * xs["b"], None

    def run(carry, xs):
        return jax.lax.scan(step, carry, xs)[0]

    good = {"a": jnp.ones((4, 3)), "b": jnp.arange(4.0)}
    f = jax.jit(checkified(run, "run"))
    err, out = f(jnp.float32(0.0), good)
    assert err.get() is None and float(out) == 18.0
    bad = {"a": good["a"].at[2, 1].set(jnp.inf), "b": good["b"]}
    err, _ = f(jnp.float32(0.0), bad)
    assert "run: input \"xs['a']\" has a non-finite value inf at index [2, 1]" in (
        err.get()
    )


def test_require_finite_under_vmap_inside_checkify():
    from jax.experimental import checkify

    def one(x, y):
        require_finite(x, "x", "mine")
        return dtw(x, y)

    f = jax.jit(checkify.checkify(jax.vmap(one, in_axes=(0, None))))
    x = jnp.zeros((3, 4, 1)).at[1, 2, 0].set(jnp.nan)
    err, out = f(x, jnp.zeros((5, 1)))
    assert "mine: input 'x' has a non-finite value nan at index [2, 0]" in err.get()
    assert np.isnan(np.asarray(out)[1]) and np.asarray(out)[0] == 0.0


def test_checked_keeps_the_result_and_raises_value_error():
    f = checked(lambda a, b: a * b, "mul")
    assert float(f(jnp.float32(2.0), 3.0)) == 6.0
    with pytest.raises(ValueError, match="mul: input 'b' has a non-finite value nan"):
        f(jnp.float32(2.0), float("nan"))
