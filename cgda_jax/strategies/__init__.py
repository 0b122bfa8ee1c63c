"""Execution strategies: FTE, IE, IET, OET on a shared batched generation step."""

from cgda_jax.strategies.base import (
    ALGORITHMS as ALGORITHMS,
    INVALID_PENALTY as INVALID_PENALTY,
    from_joints as from_joints,
    make_algorithm as make_algorithm,
    to_joints as to_joints,
)
from cgda_jax.strategies.fte import run_fte as run_fte
from cgda_jax.strategies.ie import run_ie as run_ie
from cgda_jax.strategies.ie_state import point_keys as point_keys
from cgda_jax.strategies.iet import run_iet as run_iet
from cgda_jax.strategies.oet import run_oet as run_oet
from cgda_jax.strategies.result import (
    ExecutionResult as ExecutionResult,
    SimulationDiverged as SimulationDiverged,
)
from cgda_jax.strategies.trials import (
    STRATEGIES as STRATEGIES,
    run_trials as run_trials,
)

__all__ = [
    "ALGORITHMS",
    "STRATEGIES",
    "ExecutionResult",
    "INVALID_PENALTY",
    "SimulationDiverged",
    "from_joints",
    "make_algorithm",
    "point_keys",
    "run_fte",
    "run_ie",
    "run_iet",
    "run_oet",
    "run_trials",
    "to_joints",
]
