"""Numerics the package shares: exact float32 matrix products on every device, and
the minimum-jerk profile on the host.

On NVIDIA GPUs from Ampere on, JAX computes float32 matrix products at its
"default" precision in TensorFloat-32 (10 mantissa bits): TEO's marker then lands
0.54 mm from MuJoCo's (measured on an H200, `benchmarks/bench_execution.py`),
against 1.3e-7 m on a CPU, and collision distances, MJX physics and CMA-ES's
covariance suffer alike.  `exact_matmuls` asks for full float32 products
(``jax_default_matmul_precision = "highest"``) unless the user chose a precision
(the ``JAX_DEFAULT_MATMUL_PRECISION`` variable or ``jax.config.update``), which is
left as it is.  On a CPU it changes nothing: its products are float32 already.

It is called where cgda_jax's programs are built, never on import: when a
`cgda_jax.Robot` is made (its kinematics, and every simulator, collision check
and physics built on it) and when a strategy's plan is made
(`cgda_jax.strategies.base.PlanBase`: CMA-ES's covariance and the fitness).  A
precision set by the user before either is kept.

`min_jerk_np` is the minimum-jerk profile in NumPy, for host code that must not
import JAX (the synthetic demonstrations, the segmentation's fits); the traced
one, with its derivatives and peaks, is `cgda_jax.sim.timing.min_jerk`.
"""

from __future__ import annotations

import numpy as np

#: The precision `exact_matmuls` sets (a ``jax.default_matmul_precision`` value).
PRECISION = "highest"


def exact_matmuls() -> str:
    """Set JAX's default matmul precision to `PRECISION` if nobody has chosen one.

    Returns:
        The precision in force afterwards (the user's, where one was set).
    """
    import jax

    if jax.config.jax_default_matmul_precision is None:
        jax.config.update("jax_default_matmul_precision", PRECISION)
    return str(jax.config.jax_default_matmul_precision)


def min_jerk_np(u: np.ndarray) -> np.ndarray:
    """Minimum-jerk progress ``10 u^3 - 15 u^4 + 6 u^5`` of ``u`` clipped to [0, 1]
    (0 before the move, 1 after it), in NumPy (float64 for float64 ``u``).

    Example:
        >>> from cgda_jax.numerics import min_jerk_np
        >>> min_jerk_np(np.array([-1.0, 0.5, 2.0])).tolist()
        [0.0, 0.5, 1.0]
    """
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10.0 - 15.0 * u + 6.0 * u**2)
