"""Running a policy: controllers (deterministic and randomised), their saved
tables, the controlled chain, the decision tree and Monte-Carlo rollouts."""
