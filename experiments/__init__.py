"""Built-in experiment configs (``cgda list``, ``cgda run NAME``).

This folder's ``*.toml`` files are installed as the package ``cgda_jax._experiments``
(see pyproject.toml): this file makes it a regular package, which an editable
install needs to find it. scripts/ is not installed.
"""
