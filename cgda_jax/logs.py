"""The library's logger (``cgda_jax``) and one-time warnings.

The CLI prints this logger's records as ``cgda: warning: ...`` lines
(`cgda_jax.cli.output.log_warnings`); in Python they reach the ``logging`` module's
handlers (by default stderr, for warnings).
"""

from __future__ import annotations

import logging

__all__ = ["log", "warn_once"]

log = logging.getLogger("cgda_jax")

_SAID: set[str] = set()


def warn_once(message: str) -> bool:
    """Log ``message`` as a warning unless this process logged it before (a model
    is often built more than once: checked, then run, then replayed).

    Returns:
        True if it was logged now.
    """
    if message in _SAID:
        return False
    _SAID.add(message)
    log.warning("%s", message)
    return True
