"""Sharded vs unsharded evaluation on 4 forced host devices (run in a subprocess,
because XLA_FLAGS must be set before JAX is imported)."""

import os
import subprocess
import sys
import textwrap

import jax
import numpy as np
import pytest

from cgda_jax.sharding import (
    pad_leading,
    population_sharding,
    resolve_devices,
    shard_leading,
)

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

# The strategies' ``devices=`` option: trials (IE, IET padded 3 -> 4) and one IE run's
# population (6 -> padded 8) split over 4 devices give the results of the unsharded
# runs, and the compiled chunks are partitioned (per-device shapes in the HLO).
STRATEGIES_SCRIPT = """
import jax, jax.numpy as jnp, numpy as np
from cgda_jax import sharding as sh
from cgda_jax.sim import MarkerScene, PaintWall, Robot, Simulator, model_path
from cgda_jax.strategies import run_ie, run_trials
from cgda_jax.strategies.ie import IEPlan
from cgda_jax.strategies.runner import compile_plan, seed_keys

assert jax.device_count() == 4, jax.devices()
robot = Robot.from_mjcf(model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"],
                        "marker")
sim = Simulator(robot, MarkerScene(), substeps=2)
goal = sim.execute(jnp.array([[0.3, 0.4, -0.5], [-0.2, 0.6, 0.3]]))
kw = dict(population_size=6, tolerance=0.02, max_generations=12, chunk_size=4)

def same(a, b):
    assert len(a) == len(b)
    for x, y in zip(a, b):
        # same per-candidate programs; only float32 rounding of fused code differs
        np.testing.assert_allclose(x.joints, y.joints, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(x.point_errors, y.point_errors, atol=1e-5)
        assert x.evaluations == y.evaluations and x.generations == y.generations

# IE trials split over 4 devices: 4 trials, one per device
ref = run_trials("ie", sim, goal, 4, **kw)
out = run_trials("ie", sim, goal, 4, devices=4, **kw)
same(out, ref)
assert out[0].info["devices"] == 4 and ref[0].info["devices"] == 1
# IET trials: 3 trials padded to 4
paint = Simulator(robot, PaintWall(jnp.array([[0.2, 0.0, 0.3], [0.0, 0.2, 0.3]])),
                  substeps=2)
pgoal = np.array([[50.0], [100.0]])
ref = run_trials("iet", paint, pgoal, 3, restarts=1, backtracks=1, **kw)
out = run_trials("iet", paint, pgoal, 3, devices="all", restarts=1, backtracks=1, **kw)
same(out, ref)
# one IE run, its population (6 -> padded 8) split over 4 devices
same([run_ie(sim, goal, devices=4, **kw)], [run_ie(sim, goal, **kw)])

s4 = sh.population_sharding()
plan = IEPlan(sim, goal, algorithm="CMA_ES", population_size=8, tolerance=0.02,
              max_generations=8, restarts=0, stagnation=None)
# trials: each device evolves 1 trial x 2 points x 8 candidates
hlo = compile_plan(plan, sh.shard_leading(seed_keys(np.arange(4)), s4),
                   chunk_size=2, sharding=s4)[1].as_text()
assert "f32[1,2,8,3]" in hlo and "f32[4,2,8,3]" not in hlo
# population: each device simulates 2 of the 8 candidates of each of the 2 points
# (one trial: the plan's step runs on the trial itself, no trials axis)
plan = IEPlan(sim, goal, algorithm="CMA_ES", population_size=8, tolerance=0.02,
              max_generations=8, restarts=0, stagnation=None, sharding=s4)
hlo = compile_plan(plan, seed_keys(np.arange(1)), chunk_size=2)[1].as_text()
assert "f32[2,2,3]" in hlo and "all-gather" in hlo
print("STRATEGIES-OK")
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


@pytest.mark.slow  # 45 s in CI; test_sharded_execute_matches_unsharded_on_4_devices stays
def test_strategies_devices_option_matches_unsharded_on_4_devices():
    assert "STRATEGIES-OK" in _run(STRATEGIES_SCRIPT)


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
    assert resolve_devices(None) is None
    assert resolve_devices(np.int64(1)).mesh.size == 1
    assert resolve_devices("all").mesh.size == jax.device_count()
    assert resolve_devices(s) is s
    for bad in ("some", 1.5, True):
        with pytest.raises(ValueError, match="devices="):
            resolve_devices(bad)
