"""The results folder, one format for every writer (``cgda run``, ``cgda demo``,
`cgda_jax.experiment.run_experiment`, the multi-process ``cgda run --trials`` and
`cgda_jax.ExecutionResult.save`) and every reader (``cgda plot``, ``cgda export``,
`cgda_jax.load_run`):

- ``config.toml``: the resolved config (a result saved from Python: its simulator
  described, `cgda_jax.sim.description`);
- ``result.json``: the summary (``kind``, ``name``, the strategy's figures, ...);
- ``arrays.npz``: the joints, executed features, goal, point errors, fitness
  history (and what a run adds: the generalization, the demonstrations, the motion);
- ``plots/`` and ``report.md`` (``cgda run``, ``cgda plot``).

Modules, in their import order:

1. :mod:`~cgda_jax.results_folder.rules`: which folder, and whether it can be used
   (`plan_folder`, `FolderError`, `FolderBusy`).
2. :mod:`~cgda_jax.results_folder.writing`: `RunFolder`, locked, written aside and
   moved into place whole.
3. :mod:`~cgda_jax.results_folder.reading`: its files read back, every failure
   naming the file (`read_json`, `read_npz`).

A folder back in Python, with its config: `cgda_jax.experiment.load.load_run`.
"""
