"""``python -m origami_jax`` runs the command line."""

import sys

from origami_jax.cli import main

sys.exit(main())
