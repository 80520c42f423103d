"""``python -m mitld_lp``: the ``mitld-lp`` command."""

from mitld_lp.cli import run

run()
