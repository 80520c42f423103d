"""Running a policy: the controlled chain, the decision tree and Monte-Carlo rollouts
(the controllers themselves, their file and their step rule are
:mod:`mitld_lp.controllers`)."""
