"""Exact answers: the optimum as a rational number, for models of modest size.

``synthesize(model, exact=True)`` and ``mitld-lp solve --exact`` take the floating-point
policy of the plain route, evaluate it in rational arithmetic on the model as written,
check in rational arithmetic that no choice improves it in any state, and improve it
(policy iteration in rationals) where one does: the optimum is then a fraction, the
bracket a point (two fractions when a truncated event leaves two models).

Where the exact probabilities come from (nothing is reconstructed from a float):

* the laws' hazards, from their parameters as written (:meth:`~mitld_lp.distributions.
  FirstOccurrence.exact_hazard`: geometric, pmf, uniform; a law with irrational
  hazards -- poisson, the scipy and discretised continuous laws -- is refused by name);
* the world's moves: a grid's from its ``slip`` as written, a PRISM world's from
  Storm's exact build of the same program (:mod:`mitld_lp.worlds.exact`); a world that
  has only floats (gymnasium, ``[python]``) is refused by name;
* the numbers as written: a model file's and a formula's decimals keep their text
  (:mod:`mitld_lp.util.decimals`);
* the product's transitions, recomputed from those factors state by state and checked
  against the float product (:mod:`mitld_lp.exact.rows`).

The modules: :mod:`~mitld_lp.exact.rows` (the product's rows in rationals),
:mod:`~mitld_lp.exact.solve` (exact evaluation and policy iteration, either sense),
:mod:`~mitld_lp.exact.stage` (the refusals, the budget, both truncation models, the
answer in the task's terms), :mod:`~mitld_lp.exact.errors` (how it stops).

Each is imported where it is used (``from mitld_lp.exact.stage import exact_answer``):
this package's own import is light, so that the command line names its errors
(:mod:`mitld_lp.exact.errors`) without loading the rational arithmetic.
"""
