"""``python -m mitld_lp``: the ``mitld-lp`` command."""

from mitld_lp.startup import command

command()
