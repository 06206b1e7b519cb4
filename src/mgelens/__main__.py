"""``python -m mgelens`` runs the command-line interface."""

import sys

from mgelens.cli import main

sys.exit(main())
