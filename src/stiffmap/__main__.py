"""``python -m stiffmap`` runs the command line."""

from stiffmap.cli.main import run

run()
