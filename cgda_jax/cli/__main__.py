"""``python -m cgda_jax.cli``: the ``cgda`` command."""

import sys

from cgda_jax.cli.app import main

sys.exit(main())
