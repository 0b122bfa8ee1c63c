"""Every algorithm of evosax's registry, as users pass it (issue 11).

Each one is built by name, as a class and as a configured instance, and either
converges on the tiny arm (one reachable goal point, small population, a per-algorithm
generation budget; "converges": its best error ends far below the start, see
`_converges`) or is refused with a clear error naming what is missing. No algorithm
ends with a non-finite state (invalid candidates are told the finite
`INVALID_PENALTY`).

One small compile per algorithm: the whole registry takes about 70 s on the 2-core
machine (60 generations of 16 candidates each).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from evosax.algorithms import algorithms as EVOSAX_REGISTRY

from cgda_jax import MarkerScene, Robot, Simulator, model_path
from cgda_jax.strategies import run_ie
from cgda_jax.strategies.base import to_joints
from cgda_jax.strategies.evolution import (
    ALGORITHMS,
    default_kwargs,
    evolution_init,
    evolution_step,
    make_algorithm,
)

POP, GENES = 16, 3
#: Constructor arguments cgda_jax cannot choose: the test passes them, as users must.
NEEDS = {"RandomSearch": "sampling_fn", "SV_CMA_ES": "num_populations",
         "SV_Open_ES": "num_populations"}
#: Algorithms that need a larger population than POP (none at present).
POPULATION: dict[str, int] = {}
#: Algorithms refused (ValueError) for the tiny arm's 3 genes and POP, and why.
REFUSED = {"LM_MA_ES": "c_c"}
#: Generation budget per algorithm (default 60).
GENERATIONS: dict[str, int] = {}


def _extra_kwargs(name):
    if name.startswith("SV_"):
        return {"num_populations": 2}
    if name == "RandomSearch":
        return {"sampling_fn": lambda key: jax.random.uniform(
            key, (GENES,), minval=-1.0, maxval=1.0)}
    return {}


@pytest.fixture(scope="module")
def arm():
    robot = Robot.from_mjcf(model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"],
                            "marker")
    sim = Simulator(robot, MarkerScene(), substeps=4)
    goal = jnp.asarray(robot.marker_position(jnp.asarray([0.4, 0.6, 0.8])),
                       jnp.float32)
    lower = jnp.asarray(sim.lower, jnp.float32)
    upper = jnp.asarray(sim.upper, jnp.float32)
    state = sim.init_state()

    def fitness(u):
        feats = jax.vmap(lambda w: sim.step(state, w)[1])(to_joints(u, lower, upper))
        return jnp.linalg.norm(feats - goal, axis=-1)

    return sim, goal, fitness


def _nonfinite_leaves(tree):
    return [jax.tree_util.keystr(path)
            for path, x in jax.tree_util.tree_leaves_with_path(tree)
            if jnp.issubdtype(jnp.asarray(x).dtype, jnp.floating)
            and not bool(jnp.all(jnp.isfinite(x)))]


def _evolve(name, fitness, generations):
    """Best error and final state of one evolution of `name` from the mid-range."""
    algo, params = make_algorithm(
        name, POPULATION.get(name, POP), GENES,
        algorithm_kwargs={**default_kwargs(name), **_extra_kwargs(name)})

    @jax.jit
    def run(key):
        evo = evolution_init(algo, params, key, fitness, GENES)

        def body(e, _):
            e, _ = evolution_step(algo, params, e, fitness, lambda e: jnp.asarray(False))
            return e, None

        return jax.lax.scan(body, evo, None, length=generations)[0]

    return run(jax.random.key(0))


def _converges(name, fitness):
    if name in REFUSED:  # a clear error, not a NaN state
        with pytest.raises(ValueError, match=REFUSED[name]):
            _evolve(name, fitness, 1)
        return None
    start = float(fitness(jnp.zeros((1, GENES)))[0])  # the mid-range posture
    evo = _evolve(name, fitness, GENERATIONS.get(name, 60))
    best = float(evo.best_fitness)
    # GuidedES keeps a NaN surrogate gradient by design ("none given"): not a state
    # the evolution uses, so it is the one leaf allowed to be non-finite
    bad = [k for k in _nonfinite_leaves(evo.algo)
           if not (name == "GuidedES" and k == ".grad")]
    assert bad == [], (name, bad)
    assert np.isfinite(best) and bool(evo.found), name
    # converged: at most a fifth of the start error (the start is ~490 mm away)
    assert best < 0.2 * start, (name, best, start)
    return best, start


def test_the_registry_is_evosax_s_whole_registry():
    assert set(ALGORITHMS) == set(EVOSAX_REGISTRY)
    assert len(ALGORITHMS) >= 30


@pytest.mark.parametrize("name", sorted(NEEDS))
def test_algorithms_that_need_arguments_name_them(name):
    with pytest.raises(ValueError, match=NEEDS[name]) as err:
        make_algorithm(name, POP, GENES)
    assert "algorithm_kwargs" in str(err.value)
    # the class as users pass it: the same clear error
    with pytest.raises(ValueError, match=NEEDS[name]):
        make_algorithm(EVOSAX_REGISTRY[name], POP, GENES)
    # with them, it builds
    algo, _ = make_algorithm(name, POP, GENES, algorithm_kwargs=_extra_kwargs(name))
    assert algo.num_dims == GENES


def test_stein_variational_population_counts_every_group():
    algo, _ = make_algorithm("SV_CMA_ES", 16, GENES,
                             algorithm_kwargs={"num_populations": 2})
    assert algo.population_size * algo.num_populations == 16
    with pytest.raises(ValueError, match="multiple of num_populations"):
        make_algorithm("SV_CMA_ES", 15, GENES, algorithm_kwargs={"num_populations": 2})


def test_too_small_population_is_refused_clearly():
    with pytest.raises(ValueError, match="DifferentialEvolution"):
        make_algorithm("DifferentialEvolution", 3, GENES)
    # an infinite cap (MR15_GA's std_max) is no reason to refuse
    make_algorithm("MR15_GA", POP, GENES)
    # LM_MA_ES's path rates c_c = population / (4^i genes) must stay below 2
    with pytest.raises(ValueError, match="c_c"):
        make_algorithm("LM_MA_ES", POP, GENES)
    make_algorithm("LM_MA_ES", POP, 10)


def test_run_ie_accepts_name_class_and_instance_of_another_algorithm(arm):
    from evosax.algorithms import Open_ES

    sim, goal, _ = arm
    kw = {"population_size": POP, "tolerance": 0.02, "max_generations": 60,
          "restarts": 0}
    by_name = run_ie(sim, goal[None], algorithm="Open_ES", **kw)
    by_class = run_ie(sim, goal[None], algorithm=Open_ES, **kw)
    # a class is built with the same defaults as its name: the same run
    np.testing.assert_array_equal(by_name.joints, by_class.joints)
    inst = Open_ES(population_size=POP, solution=jnp.zeros(GENES),
                   **default_kwargs("Open_ES"))
    by_instance = run_ie(sim, goal[None], algorithm=inst, **kw)
    np.testing.assert_allclose(by_instance.joints, by_name.joints, atol=1e-6)
    assert by_name.point_errors.max() < 0.1


@pytest.mark.parametrize("name", sorted(ALGORITHMS))
def test_every_registry_algorithm_converges_on_the_tiny_arm(arm, name):
    _, _, fitness = arm
    _converges(name, fitness)
