"""Built-in MJCF models (robots; object pieces in objects/).

This folder is installed as the package ``cgda_jax._models`` (see pyproject.toml):
this file makes it a regular package, which an editable install needs to find it.
Look models up with ``cgda_jax.model_path(name)``.
"""
