"""``python -m origami_jax`` runs the command line."""

import sys

from origami_jax.cli import console_main

sys.exit(console_main())
