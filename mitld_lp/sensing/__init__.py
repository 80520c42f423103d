"""Events the robot learns of through sensors that miss (docs/semantics.md, "Sensors").

* :mod:`~mitld_lp.sensing.sensors`: the :class:`Sensor` record and the ``[sensors]``
  table of a model file;
* :mod:`~mitld_lp.sensing.belief`: the information-state product (the MDP over what the
  robot knows), built a frontier at a time by :mod:`~mitld_lp.sensing.frontier` (its
  array operations in :mod:`~mitld_lp.sensing.rows`) from the step rules of
  :mod:`~mitld_lp.sensing.rules`, its records in :mod:`~mitld_lp.sensing.info`, the
  controller's moves in :mod:`~mitld_lp.sensing.moves`, its budgets (the exact check
  before each batch, the estimate of its final size at each level's end) in
  :mod:`~mitld_lp.sensing.growth`, the states whose futures are identical merged by
  :mod:`~mitld_lp.sensing.merge`;
* :mod:`~mitld_lp.sensing.horizon`: the sensors whose reports come too late for the
  task, built as blind ones (the same optimum);
* :mod:`~mitld_lp.routes.sensed_solve`: the ``sensed`` route, its certified bracket (the one
  :class:`~mitld_lp.result.Result`, with its ``sensors`` and ``belief`` parts);
* :mod:`~mitld_lp.sensing.table`: its policy table;
* :mod:`~mitld_lp.sensing.observe`: the controller that acts on observations made from
  the information states (the controller itself, its file and its step rule are
  :mod:`mitld_lp.controllers`, with every other kind), and the simulation that draws the
  hidden events and the sensors' reports;
* :mod:`~mitld_lp.sensing.saved`: ``load_sensed``, where it was (the one reader loads
  every controller file).
"""

from mitld_lp.sensing.sensors import Sensor

__all__ = ["Sensor"]
