"""``cgda list``: the built-in experiments, one line each."""

from __future__ import annotations

from cgda_jax.cli.output import EXIT_MET


def cmd_list(args) -> int:
    from cgda_jax.builtin import experiment_lines

    print("\n".join(experiment_lines()))
    return EXIT_MET
