"""Subcommands of the `formation` command line (see formation_sim.cli)."""
