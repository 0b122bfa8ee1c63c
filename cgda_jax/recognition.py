"""Recognition: compare query trajectories with a library of generalized actions.

Queries and actions are both brought to ``n_samples`` equally spaced normalized
times in [0, 1] (paper 2.2: "as the query and the generalized actions are
normalized in time, we can take t values along time for each action"); the
(Q, A) cost matrix is then one batched ``vmap(vmap(metric))`` call, and the
recognized action of each query is the argmin of its row.

References:
    Morante et al., "Humanoid Robot Imitation through Continuous Goal-Directed
    Actions: An Evolutionary Approach", Advanced Robotics 2015, section 2.2.
"""

from __future__ import annotations

import functools
from collections.abc import Iterator, Mapping, Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from cgda_jax.checks import check_float32
from cgda_jax.data import Demonstration
from cgda_jax.distance import dtw, dtw_multi, euclidean, resample
from cgda_jax.generalization import GeneralizedAction, generalize, sample_actions
from cgda_jax.sizes import check_recognition

__all__ = ["ActionLibrary", "Recognition", "cost_matrix", "recognize", "METRICS"]

METRICS = {"dtw": dtw, "dtw_multi": dtw_multi, "euclidean": euclidean}


class ActionLibrary(Mapping[str, GeneralizedAction]):
    """An ordered, name-keyed collection of generalized actions (same features).

    Args:
        actions: GeneralizedActions (keyed by their ``name``) or a mapping
            name -> GeneralizedAction.
    """

    def __init__(
        self,
        actions: Sequence[GeneralizedAction] | Mapping[str, GeneralizedAction] = (),
    ):
        items = (
            list(actions.items())
            if isinstance(actions, Mapping)
            else [(a.name, a) for a in actions]
        )
        self._actions: dict[str, GeneralizedAction] = {}
        for name, action in items:
            self.add(action, name=name)

    @classmethod
    def from_demonstrations(
        cls,
        demos: Mapping[str, Sequence[Demonstration]],
        interval_s: float = 1.0,
        method: str = "paper",
    ) -> ActionLibrary:
        """Generalize each action's demonstrations (``{name: [demo, ...]}``)."""
        return cls(
            {
                name: generalize(d, interval_s=interval_s, method=method, name=name)
                for name, d in demos.items()
            }
        )

    def add(self, action: GeneralizedAction, name: str | None = None) -> None:
        """Add an action under ``name`` (default: ``action.name``)."""
        name = action.name if name is None else name
        if not isinstance(action, GeneralizedAction):
            raise ValueError(f"{name!r} is {type(action).__name__}, not an action")
        if name in self._actions:
            raise ValueError(f"action {name!r} is already in the library")
        if self._actions:
            first = next(iter(self._actions.values()))
            if action.feature_names != first.feature_names:
                raise ValueError(
                    f"action {name!r} has features {action.feature_names} but the "
                    f"library has {first.feature_names}"
                )
        self._actions[name] = action

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self._actions)

    @property
    def feature_names(self) -> tuple[str, ...]:
        if not self._actions:
            return ()
        return next(iter(self._actions.values())).feature_names

    def __getitem__(self, name: str) -> GeneralizedAction:
        try:
            return self._actions[name]
        except KeyError:
            raise KeyError(
                f"no action {name!r} in the library; have {self.names}"
            ) from None

    def __iter__(self) -> Iterator[str]:
        return iter(self._actions)

    def __len__(self) -> int:
        return len(self._actions)

    def sample(self, n: int) -> jax.Array:
        """(A, n, F) every action at ``n`` equally spaced normalized times."""
        if not self._actions:
            raise ValueError("the action library is empty")
        return sample_actions(tuple(self._actions.values()), n)


def _query_array(
    q: Demonstration | np.ndarray | jax.Array,
    k: int,
    n: int,
    feature_names: tuple[str, ...],
) -> jax.Array:
    """One query resampled to (n, F) at equally spaced normalized times."""
    if isinstance(q, Demonstration):
        if feature_names and q.feature_names != feature_names:
            raise ValueError(
                f"query {k} ({q.name!r}) has features {q.feature_names} but the "
                f"library has {feature_names}"
            )
        t = np.linspace(0.0, 1.0, n)
        tq = q.normalized_times
        cols = [np.interp(t, tq, q.features[:, f]) for f in range(q.n_features)]
        return np.stack(cols, axis=1).astype(np.float32)
    # NaN, inf or beyond float32 (inf once cast), named with its index
    check_float32(q, f"query {k}", where="cost_matrix")
    # float32 and resampled in `_pairwise` (one program, not a few per query)
    arr = q if isinstance(q, jax.Array) else np.asarray(q, np.float32)
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2 or arr.shape[0] < 2:
        raise ValueError(
            f"query {k} must be a Demonstration or a (T, F) array with T >= 2, "
            f"got shape {arr.shape}"
        )
    if feature_names and arr.shape[1] != len(feature_names):
        raise ValueError(
            f"query {k} has {arr.shape[1]} features but the library has "
            f"{len(feature_names)} {feature_names}"
        )
    return arr


def cost_matrix(
    queries: Sequence[Demonstration | np.ndarray | jax.Array],
    library: ActionLibrary,
    metric: str = "dtw",
    n_samples: int = 100,
) -> jax.Array:
    """Discrepancy of every query against every library action.

    Args:
        queries: Q query trajectories: Demonstrations (resampled by their own
            normalized times) or (T, F) arrays (taken as uniformly sampled over
            normalized time [0, 1]).
        library: A generalized actions.
        metric: ``"dtw"`` (paper), ``"dtw_multi"`` or ``"euclidean"``.
        n_samples: samples per trajectory after time normalization.

    Returns:
        (Q, A) costs; lower is more similar.

    Raises:
        ValueError: a bad metric, library, query or sample count.
        cgda_jax.sizes.SizeError: `n_samples` too large for the memory, XLA's
            32-bit sizes or `cgda_jax.sizes.MAX_DTW_CELLS` (before allocating).
    """
    if metric not in METRICS:
        raise ValueError(f"unknown metric {metric!r}; expected one of {tuple(METRICS)}")
    if len(library) == 0:
        raise ValueError("the action library is empty")
    if isinstance(queries, Demonstration):
        queries = [queries]
    if len(queries) == 0:
        raise ValueError("no queries given")
    if isinstance(n_samples, bool) or int(n_samples) != n_samples or n_samples < 2:
        raise ValueError(f"n_samples must be a whole number >= 2, got {n_samples!r}")
    n_samples = int(n_samples)
    names = library.feature_names
    # before anything is resampled: memory, XLA's 32-bit sizes, DTW work
    check_recognition(len(queries), len(library), n_samples, max(len(names), 1),
                      metric=metric)
    q = tuple(_query_array(x, k, n_samples, names) for k, x in enumerate(queries))
    return _pairwise(METRICS[metric], n_samples, q, tuple(library.values()))


@functools.partial(jax.jit, static_argnums=(0, 1))
def _pairwise(
    metric,
    n_samples: int,
    queries: tuple[jax.Array, ...],
    actions: tuple[GeneralizedAction, ...],
) -> jax.Array:
    """(Q, A) costs: the queries ((T_k, F) each) resampled to ``n_samples`` and the
    actions sampled there, all in the one program of the metric."""
    q = jnp.stack([resample(jnp.asarray(x, jnp.float32), n_samples) for x in queries])
    refs = sample_actions(actions, n_samples)
    per_query = jax.vmap(metric, in_axes=(None, 0))
    return jax.vmap(per_query, in_axes=(0, None))(q, refs)


class Recognition(NamedTuple):
    """Result of :func:`recognize`: per query the best action and all costs."""

    indices: np.ndarray  # (Q,) index of the recognized action
    names: list[str]  # (Q,) name of the recognized action
    costs: np.ndarray  # (Q, A) cost matrix


def recognize(
    queries: Sequence[Demonstration | np.ndarray | jax.Array],
    library: ActionLibrary,
    metric: str = "dtw",
    n_samples: int = 100,
) -> Recognition:
    """Recognize each query as the library action of least cost (argmin per row).

    Args: as :func:`cost_matrix`.

    Returns:
        Recognition(indices (Q,), names, costs (Q, A)).
    """
    costs = np.asarray(cost_matrix(queries, library, metric, n_samples))
    idx = np.argmin(costs, axis=1)
    return Recognition(idx, [library.names[i] for i in idx], costs)
