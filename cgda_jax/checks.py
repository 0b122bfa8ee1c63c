"""Finite-value checks for arrays entering the library, eager and under ``jit``.

The rule the numeric kernels follow (`cgda_jax.distance`, `cgda_jax.rbf_interpolate`):

* **Eager calls** (concrete arrays) check their inputs on the host and raise
  ``ValueError`` naming the input and the index of its first bad value
  (`check_finite`).
* **Traced calls** (inside ``jit``, ``vmap``, ``scan``, ``grad``) cannot raise on a
  value without a host sync, so they check nothing and return **NaN** for an input
  with a NaN or an infinity.  The hot path stays free of host syncs.
* To find out *which* input was bad in jitted code, wrap the function with `checked`
  (one jitted call that raises ``ValueError`` naming the input), or with `checkified`
  (a pure ``(error, out)`` function for your own jitted step or scan: throw the
  error once per chunk, not per call).  Both use ``jax.experimental.checkify``.

Example:
    >>> import jax, jax.numpy as jnp
    >>> from cgda_jax import dtw
    >>> from cgda_jax.checks import checked
    >>> x = jnp.array([[0.0], [1.0], [2.0]])
    >>> bad = x.at[1, 0].set(jnp.nan)
    >>> bool(jnp.isnan(jax.jit(dtw)(bad, x)))           # traced: a NaN result
    True
    >>> checked(dtw)(bad, x)                            # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: dtw: input 'x' has a non-finite value nan at index [1, 0]...
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.experimental import checkify

__all__ = [
    "FLOAT32_MAX",
    "check_finite",
    "check_float32",
    "checked",
    "checkified",
    "is_traced",
    "require_finite",
]

#: Largest finite float32; values beyond it become ``inf`` when cast to float32.
FLOAT32_MAX = float(np.finfo(np.float32).max)


def is_traced(x: Any) -> bool:
    """True if ``x`` is a JAX tracer (its value is unknown until run)."""
    return isinstance(x, jax.core.Tracer)


def _index_text(index: tuple[int, ...]) -> str:
    return "[" + ", ".join(str(int(i)) for i in index) + "]"


def check_finite(
    x: Any, name: str, *, where: str = "", limit: float | None = None
) -> None:
    """Raise ``ValueError`` if a concrete array holds a NaN or an infinity.

    A traced ``x`` is not checked (see the module docstring).

    Args:
        x: array-like.
        name: the input's name, used in the message.
        where: optional prefix naming the function or file, e.g. ``"dtw"``.
        limit: also refuse finite values with ``|x| > limit`` (e.g. `FLOAT32_MAX`).

    Raises:
        ValueError: ``"{where}: input '{name}' has a non-finite value nan at index
            [i, j]"`` (first bad value in C order).
    """
    if is_traced(x):
        return
    arr = np.asarray(x)
    if not np.issubdtype(arr.dtype, np.floating):
        return
    bad = ~np.isfinite(arr)
    if limit is not None:
        bad |= np.abs(np.where(bad, 0, arr)) > limit
    if not bad.any():
        return
    index = np.unravel_index(int(np.argmax(bad.ravel())), arr.shape)
    value = float(arr[index])
    if np.isfinite(value):
        what = f"a value {value:g} beyond +/-{limit:.4g} (float32 overflows)"
    else:
        what = f"a non-finite value {value:g}"
    prefix = f"{where}: " if where else ""
    raise ValueError(
        f"{prefix}input {name!r} has {what} at index {_index_text(index)}"
    )


def check_float32(x: Any, name: str, *, where: str = "") -> None:
    """`check_finite` that also refuses values that overflow float32 (``|x| >
    FLOAT32_MAX``), for float64 host data about to be cast to float32."""
    check_finite(x, name, where=where, limit=FLOAT32_MAX)


def require_finite(x: jax.Array, name: str, where: str = "") -> None:
    """Inside a function transformed by ``checkify.checkify``: a check that every
    value of ``x`` is finite, whose error names ``name`` and the first bad index.

    Works under ``jit`` and ``vmap``; it records an error instead of syncing with the
    host.  Outside ``checkify`` it raises, so call it from code meant to be checked.
    """
    x = jnp.asarray(x)
    if not jnp.issubdtype(x.dtype, jnp.floating):
        return
    bad = ~jnp.isfinite(x)
    flat = jnp.argmax(bad.ravel())
    index = jnp.unravel_index(flat, x.shape) if x.ndim else ()
    value = x.ravel()[flat] if x.ndim else x
    prefix = f"{where}: " if where else ""
    slots = ", ".join("{}" for _ in index)
    checkify.check(
        ~jnp.any(bad),
        f"{prefix}input {name!r} has a non-finite value {{}} at index [{slots}]",
        value,
        *index,
    )


def _check_arguments(fn: Callable, where: str, args: tuple, kwargs: dict) -> None:
    try:
        bound = inspect.signature(fn).bind(*args, **kwargs)
        named = list(bound.arguments.items())
    except (TypeError, ValueError):  # no signature: number the positional inputs
        named = [(f"arg{k}", a) for k, a in enumerate(args)] + list(kwargs.items())
    for name, value in named:
        leaves = jax.tree_util.tree_leaves_with_path(value)
        for path, leaf in leaves:
            if isinstance(leaf, (jax.Array, np.ndarray, np.generic, float)):
                label = name + jax.tree_util.keystr(path)
                require_finite(leaf, label, where)


def checkified(fn: Callable, name: str | None = None) -> Callable:
    """``fn`` with finite checks on every floating input, as a pure function.

    Returns ``g(*args, **kwargs) -> (error, out)`` (``jax.experimental.checkify``):
    jit it, scan it or call it inside your own jitted step, and call
    ``error.throw()`` (or read ``error.get()``) on the host when convenient, e.g. once
    per chunk of generations.  ``error.throw()`` raises ``checkify.JaxRuntimeError``
    (a ``ValueError``) naming the input (argument name, pytree path) and its first
    bad index.

    Args:
        fn: a JAX function, e.g. `cgda_jax.dtw` or ``jax.vmap(dtw, in_axes=(0,
            None))`` (then the index includes the batch axis).
        name: the function's name in the message (default ``fn.__name__``).
    """
    where = name or getattr(fn, "__name__", "function")

    def body(*args, **kwargs):
        _check_arguments(fn, where, args, kwargs)
        return fn(*args, **kwargs)

    return checkify.checkify(body)


def checked(
    fn: Callable, name: str | None = None, *, static_argnames: tuple[str, ...] = ()
) -> Callable:
    """``fn`` jitted with finite checks on its inputs; raises ``ValueError`` naming
    the bad input.

    Each call is one jitted computation plus one host sync to read the error: use it
    where an error must stop the program at once (tests, data preparation); inside a
    hot loop use `checkified` and throw per chunk.

    Args:
        fn: a JAX function (see `checkified`).
        name: the function's name in the message (default ``fn.__name__``).
        static_argnames: arguments of ``fn`` that are static to ``jit`` (e.g.
            ``("n_samples",)`` for `cgda_jax.euclidean`); pass them by keyword.

    Returns:
        A function with ``fn``'s arguments and result.
    """
    jitted = jax.jit(checkified(fn, name), static_argnames=static_argnames)

    @functools.wraps(fn)
    def run(*args, **kwargs):
        err, out = jitted(*args, **kwargs)
        message = err.get()  # the one host sync
        if message is not None:
            raise ValueError(message.split("\n")[0].removesuffix(" (`check` failed)"))
        return out

    return run
