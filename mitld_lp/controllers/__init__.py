"""The controller: what a synthesis hands the robot, how it acts, how it is saved and read.

Two floors, so that a robot's process (:mod:`mitld_lp.runtime`, ``mitld-lp run``) reads
and runs a saved controller with NumPy alone:

* NumPy and the standard library only (nothing else of the package but
  :mod:`mitld_lp.files.rules`): :mod:`~mitld_lp.controllers.observation` (the one
  :class:`Observation`: world state, events seen, sensor reports received; the task's
  :class:`RunStatus`), :mod:`~mitld_lp.controllers.format` (the file format: its
  layout per kind and version, the state encoding, the one writer),
  :mod:`~mitld_lp.controllers.stepper` (the one step rule, :class:`Stepper`, and the
  memory rule of an automaton with a clock), :mod:`~mitld_lp.controllers.tables` (the
  saved tables and their answers: :class:`SavedPlan` for a deterministic or randomised
  controller, :class:`SensedPlan` for one that acts on sensor reports,
  :class:`MixedSensedPlan` for a randomised one over information states) and
  :mod:`~mitld_lp.controllers.reader` (the one reader, one set of checks for every kind
  and every version);
* above them, with the synthesis's records: :mod:`~mitld_lp.controllers.live` (a
  synthesis's model as a plan, and its tables for saving) and
  :mod:`~mitld_lp.controllers.kinds` (the controller classes: deterministic, randomised,
  sensed, randomised sensed, which differ only in their plan, and
  :func:`load_controller`).

This file imports nothing, so that importing a module of the lower floor loads nothing
of the upper one.
"""
