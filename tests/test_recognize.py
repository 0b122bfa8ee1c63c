"""ActionLibrary, cost_matrix and recognize on a small generated action set."""

import numpy as np
import pytest

from cgda_jax.data import Demonstration
from cgda_jax.distance import dtw, euclidean
from cgda_jax.recognition import ActionLibrary, cost_matrix, recognize

NAMES = ("x", "y", "z")


def _shape(action, s):
    if action == "move":
        return np.stack([0.3 * s, 0 * s, 0 * s], 1)
    if action == "circle":
        return np.stack([np.cos(2 * np.pi * s) - 1, np.sin(2 * np.pi * s), 0 * s], 1)
    if action == "lift":
        return np.stack([0 * s, 0 * s, 0.5 * np.sin(np.pi * s)], 1)
    return np.stack([0.2 * s, 0.2 * s, 0.2 * s**2], 1)  # "diag"


def _set(seed, n_reps):
    rng = np.random.default_rng(seed)
    out = {}
    for a in ("move", "circle", "lift", "diag"):
        reps = []
        for k in range(n_reps):
            dur = rng.uniform(8, 12)
            t = np.sort(rng.uniform(0, dur, 80))
            t[0], t[-1] = 0.0, dur
            s = (t / dur) ** rng.uniform(0.9, 1.1)
            feats = _shape(a, s) + 0.01 * rng.normal(size=(80, 3))
            reps.append(Demonstration(t + rng.uniform(0, 50), feats, NAMES, f"{a}{k}"))
        out[a] = reps
    return out


@pytest.fixture(scope="module")
def library():
    return ActionLibrary.from_demonstrations(_set(0, 6), interval_s=1.0)


@pytest.mark.parametrize("metric", ["dtw", "dtw_multi", "euclidean"])
def test_every_test_trajectory_is_recognized_as_its_action(library, metric):
    test = _set(1, 1)
    queries = [reps[0] for reps in test.values()]
    result = recognize(queries, library, metric=metric, n_samples=40)
    assert result.names == list(test)
    assert result.costs.shape == (4, 4)
    np.testing.assert_array_equal(result.indices, np.arange(4))


def test_cost_matrix_entries_equal_single_pair_metrics(library):
    rng = np.random.default_rng(3)
    q_arr = rng.normal(size=(25, 3)).astype(np.float32)
    q_demo = _set(2, 1)["lift"][0]
    costs = np.asarray(cost_matrix([q_arr, q_demo], library, "dtw", n_samples=30))
    tq = np.linspace(0, 1, 30)
    demo_res = np.stack(
        [np.interp(tq, q_demo.normalized_times, q_demo.features[:, f])
         for f in range(3)],
        1,
    )
    arr_res = np.stack(
        [np.interp(tq, np.linspace(0, 1, 25), q_arr[:, f]) for f in range(3)], 1
    )
    for a, name in enumerate(library.names):
        ref = np.asarray(library[name].sample(30))
        np.testing.assert_allclose(costs[0, a], float(dtw(arr_res, ref)), rtol=1e-5)
        np.testing.assert_allclose(costs[1, a], float(dtw(demo_res, ref)), rtol=1e-5)
    e = np.asarray(cost_matrix([q_arr], library, "euclidean", n_samples=30))
    ref0 = np.asarray(library[library.names[0]].sample(30))
    np.testing.assert_allclose(e[0, 0], float(euclidean(arr_res, ref0)), rtol=1e-5)


def test_library_and_recognition_errors(library):
    with pytest.raises(ValueError, match="unknown metric 'cosine'"):
        cost_matrix([np.zeros((5, 3))], library, metric="cosine")
    with pytest.raises(ValueError, match="query 0 has 2 features"):
        cost_matrix([np.zeros((5, 2))], library)
    t = np.linspace(0, 1, 5)
    wrong = Demonstration(t, np.zeros((5, 3)), ("a", "b", "c"), "wrong")
    with pytest.raises(ValueError, match=r"query 0 \('wrong'\) has features"):
        cost_matrix([wrong], library)
    with pytest.raises(ValueError, match=r"cost_matrix: input 'query 1' has a "
                       r"non-finite value nan at index \[0, 0\]"):
        cost_matrix([np.zeros((5, 3)), np.full((5, 3), np.nan)], library)
    big = np.zeros((5, 3))
    big[3, 2] = 1e39  # inf once cast to float32
    with pytest.raises(ValueError, match=r"input 'query 0' has a value 1e\+39 beyond "
                       r".* \(float32 overflows\) at index \[3, 2\]"):
        cost_matrix([big], library)
    with pytest.raises(ValueError, match="no queries"):
        cost_matrix([], library)
    with pytest.raises(ValueError, match="library is empty"):
        cost_matrix([np.zeros((5, 3))], ActionLibrary())
    with pytest.raises(KeyError, match="no action 'swim'"):
        library["swim"]
    with pytest.raises(ValueError, match="'move' is already in the library"):
        ActionLibrary([library["move"], library["move"]])
