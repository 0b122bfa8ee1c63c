"""The ``cgda`` command: ``cgda run CONFIG``, ``cgda demo``, ``cgda list``,
``cgda plot FOLDER`` (and ``cgda run --trials N``).

Argument parsing, the JAX compilation cache, progress and error reporting only; the
work is done by :mod:`cgda_jax.experiment`. Nothing of the library imports this
package.

Modules, in their import order (each imports only those above it; none imports
this ``__init__``):

- :mod:`~cgda_jax.cli.output`: what the commands share: `Session` (what a process
  holds besides its arguments: its results folder, its job, whether it is quiet),
  `say` (progress lines on stderr), the JAX compilation cache, exit statuses
  (``EXIT_*``), which errors are bad input, signals, saved tracebacks, library
  warnings as lines.
- :mod:`~cgda_jax.cli.list`: ``cgda list``.
- :mod:`~cgda_jax.cli.plot`: ``cgda plot``.
- :mod:`~cgda_jax.cli.segment`: ``cgda segment`` (the actions in one recording).
- :mod:`~cgda_jax.cli.trials`: ``cgda run --trials N`` (and its worker processes).
- :mod:`~cgda_jax.cli.run`: ``cgda run``.
- :mod:`~cgda_jax.cli.demo`: ``cgda demo``.
- :mod:`~cgda_jax.cli.app`: the parser, the dispatch to a command and `main` (the
  ``cgda`` console script, also ``python -m cgda_jax.cli``).
"""

from cgda_jax.cli.app import main as main
from cgda_jax.cli.output import (
    EXIT_DIVERGED as EXIT_DIVERGED,
    EXIT_FAILURE as EXIT_FAILURE,
    EXIT_MET as EXIT_MET,
    EXIT_NOT_MET as EXIT_NOT_MET,
    EXIT_SIGNAL as EXIT_SIGNAL,
    EXIT_USAGE as EXIT_USAGE,
    USER_ERRORS as USER_ERRORS,
    Interrupted as Interrupted,
    enable_compilation_cache as enable_compilation_cache,
)

__all__ = ["EXIT_DIVERGED", "EXIT_FAILURE", "EXIT_MET", "EXIT_NOT_MET", "EXIT_SIGNAL",
           "EXIT_USAGE", "USER_ERRORS", "Interrupted", "enable_compilation_cache",
           "main"]
