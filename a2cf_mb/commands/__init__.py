"""CLI subcommands, one module each (see :mod:`a2cf_mb.cli`)."""
