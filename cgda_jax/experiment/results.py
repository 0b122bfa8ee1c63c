"""A run's results folder, for the experiment layer: `RunFolder` (locked, written
aside, moved into place at the end) and the checks of `plan_folder`. The rules and
the code are those of `cgda_jax.folders` and `cgda_jax.run_folder`, shared with
`cgda_jax.ExecutionResult.save` and the multi-process ``cgda run``; this module
re-exports them where the experiment layer has always found them.
"""

from __future__ import annotations

from cgda_jax.folders import (
    MARKER,
    FolderBusy,
    FolderError,
    check_writable,
    expand,
    follow_link,
    plan_folder,
)
from cgda_jax.run_folder import RunFolder

__all__ = ["MARKER", "FolderBusy", "FolderError", "RunFolder", "check_writable",
           "expand", "follow_link", "plan_folder"]
