"""``python -m a2cf_mb`` runs the CLI."""

import sys

from a2cf_mb.cli import main

sys.exit(main())
