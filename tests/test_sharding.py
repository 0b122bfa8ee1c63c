"""Sharded vs unsharded evaluation on 4 forced host devices (run in a subprocess,
because XLA_FLAGS must be set before JAX is imported)."""

import os
import subprocess
import sys
import textwrap

import jax
import numpy as np
import pytest

from cgda_jax.sharding import pad_leading, population_sharding, shard_leading

SCRIPT = textwrap.dedent(
    """
    import jax, jax.numpy as jnp, numpy as np
    from cgda_jax import sharding as sh
    from cgda_jax.sim import MarkerScene, Robot, Simulator, model_path

    assert jax.device_count() == 4, jax.devices()
    robot = Robot.from_mjcf(model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"],
                            "marker")
    sim = Simulator(robot, MarkerScene(), substeps=2)
    s4 = sh.population_sharding()
    rng = np.random.default_rng(0)
    for p in (8, 10, 3):  # divisible, padded, fewer candidates than devices
        pop = jnp.asarray(rng.uniform(-1, 1, (p, 5, 3)), jnp.float32)
        ref = np.asarray(sim.execute_population(pop))
        out = sh.sharded_execute(sim.execute_population, pop, s4)
        assert out.shape == ref.shape, (out.shape, ref.shape)
        np.testing.assert_allclose(np.asarray(out), ref, rtol=1e-6, atol=1e-6)
        if p == 8:
            assert len(out.sharding.device_set) == 4, out.sharding
            # Each device computes only its 2 candidates (not a replicated 8).
            hlo = jax.jit(sh.shard_population(sim.execute_population, s4)).lower(
                pop).compile().as_text()
            assert "f32[2,5,3]" in hlo and "f32[8,5,3]" not in hlo
        # Inside a user's jit, with a reduction after it (a fitness).
        fit = jax.jit(lambda x: sh.shard_population(
            sim.execute_population, s4)(x).sum(axis=(1, 2)))(pop)
        np.testing.assert_allclose(np.asarray(fit), ref.sum(axis=(1, 2)), rtol=1e-5)
    # Placed input keeps the split: each device holds 2 of 8 rows.
    placed = sh.shard_leading(np.zeros((8, 5, 3), np.float32), s4)
    assert sorted(s.data.shape[0] for s in placed.addressable_shards) == [2, 2, 2, 2]
    try:
        sh.shard_leading(np.zeros((10, 3)), s4)
    except ValueError as e:
        assert "not divisible by the 4 devices" in str(e), e
    else:
        raise AssertionError("no error for 10 rows on 4 devices")
    print("SHARDING-OK")
    """
)

# A strategy (IE) whose R = 4 trials are split over 4 devices with `axis_shardings`,
# the way a runner given a sharding would jit its init and chunk functions; it must
# give the same result per seed as the unsharded `drive`.
TRIALS_SCRIPT = """
import jax, jax.numpy as jnp, numpy as np
from cgda_jax import sharding as sh
from cgda_jax.sim import MarkerScene, Robot, Simulator, model_path
from cgda_jax.strategies.ie import IEPlan
from cgda_jax.strategies.runner import drive, seed_keys

robot = Robot.from_mjcf(model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"],
                        "marker")
sim = Simulator(robot, MarkerScene(), substeps=2)
goal = sim.execute(jnp.array([[0.3, 0.4, -0.5], [-0.2, 0.6, 0.3]]))
plan = IEPlan(sim, goal, algorithm="CMA_ES", population_size=8, tolerance=0.02,
              max_generations=20)
keys = seed_keys(np.arange(4))
ref = drive(plan, keys, chunk_size=5)

# The same plan, its 4 trials split over 4 devices (a runner with a sharding).
s4 = sh.population_sharding()
chunk = lambda c: jax.lax.scan(lambda c, _: jax.vmap(plan.step)(c), c, None, length=5)
carry_shape = jax.eval_shape(jax.vmap(plan.init), keys)
metric_shape = jax.eval_shape(chunk, carry_shape)[1]
cs = sh.axis_shardings(carry_shape, s4)
init_c = jax.jit(jax.vmap(plan.init), in_shardings=s4, out_shardings=cs)
chunk_c = jax.jit(chunk, in_shardings=(cs,),
                  out_shardings=(cs, sh.axis_shardings(metric_shape, s4, axis=1)))
carry = init_c(sh.shard_leading(keys, s4))
for _ in range(4):
    carry, _ = chunk_c(carry)
    if bool(jnp.all(jax.vmap(plan.done)(carry))):
        break
assert len(carry.best_u.sharding.device_set) == 4, carry.best_u.sharding
hlo = chunk_c.lower(carry).compile().as_text()
assert "f32[1,2,8,3]" in hlo, "each device should evolve 1 trial x 2 points x 8"
final = jax.tree.map(np.asarray, jax.vmap(plan.finish)(carry))
for r, res in enumerate(ref):
    np.testing.assert_allclose(final["joints"][r], res.joints, rtol=1e-5, atol=1e-6)
print("TRIALS-OK")
"""


def _run(script: str, n_devices: int = 4) -> str:
    env = dict(os.environ)
    env["XLA_FLAGS"] = (
        env.get("XLA_FLAGS", "")
        + f" --xla_force_host_platform_device_count={n_devices}"
    )
    env["JAX_PLATFORMS"] = "cpu"
    proc = subprocess.run(
        [sys.executable, "-c", script],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout


def test_sharded_execute_matches_unsharded_on_4_devices():
    assert "SHARDING-OK" in _run(SCRIPT)


def test_sharded_strategy_trials_match_unsharded_on_4_devices():
    pytest.importorskip("cgda_jax.strategies.runner")
    assert "TRIALS-OK" in _run(TRIALS_SCRIPT)


def test_pad_leading_repeats_last_row():
    x = np.arange(10.0).reshape(5, 2)
    tree = {"a": x, "b": x[:, 0]}
    out = pad_leading(tree, 4)
    assert out["a"].shape == (8, 2) and out["b"].shape == (8,)
    np.testing.assert_array_equal(out["a"][5:], np.repeat(x[-1:], 3, axis=0))
    assert pad_leading(tree, 5) is tree
    with pytest.raises(ValueError, match="same leading"):
        pad_leading({"a": x, "b": x[:3]}, 4)


def test_single_device_mesh_and_errors():
    s = population_sharding()
    assert s.mesh.shape["pop"] == jax.device_count()
    np.testing.assert_array_equal(shard_leading(np.ones((3, 2)), s), np.ones((3, 2)))
    with pytest.raises(ValueError, match="n_devices=99"):
        population_sharding(99)
