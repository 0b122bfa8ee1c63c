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
