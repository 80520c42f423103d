"""Events the robot learns of through sensors that miss (docs/semantics.md, "Sensors").

* :mod:`~mitld_lp.sensing.sensors`: the :class:`Sensor` record and the ``[sensors]``
  table of a model file;
* :mod:`~mitld_lp.sensing.belief`: the information-state product (the MDP over what the
  robot knows);
* :mod:`~mitld_lp.sensing.solve`: the ``sensed`` route, its certified bracket
  (:class:`~mitld_lp.sensing.solve.SensedResult`);
* :mod:`~mitld_lp.sensing.observe`: :class:`~mitld_lp.sensing.observe.Observation`, the
  controller that acts on observations, and the simulation that draws the hidden events
  and the sensors' reports.
"""

from mitld_lp.sensing.sensors import Sensor

__all__ = ["Sensor"]
