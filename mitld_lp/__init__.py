"""mitld_lp: policy synthesis for MITLD (Metric Interval Temporal Logic with distribution
eventualities) by occupancy-measure linear programming.

``import mitld_lp`` loads no solver stack (cvxpy, Clarabel, HiGHS, scipy's linear
algebra, ``mitld_lp.solvers``): :func:`synthesize` imports it at its first solve
(tests/test_imports.py checks this in a fresh interpreter).  The public names are
loaded from their modules on first use, so that :mod:`mitld_lp.runtime` (a saved
controller, NumPy alone) imports nothing else of the package.  The package's modules
import with Python's garbage collector held (put back as the program had it) and their
dataclasses made without ``exec`` (:mod:`mitld_lp.own_imports`).
"""

from mitld_lp import startup  # noqa: F401 - first: Ctrl-C while the command line imports

# isort: split
import importlib
import importlib.util
import sys
import types
from typing import TYPE_CHECKING, Any

startup.package_imports_held()  # the package's modules import with the collector held

if TYPE_CHECKING:  # what the names are, for type checkers and readers
    from mitld_lp.automata.dta import DTA
    from mitld_lp.automata.sta import STA, make_sta
    from mitld_lp.automata.translate import to_dta
    from mitld_lp.controllers.format import ControllerFileError
    from mitld_lp.controllers.kinds import (
        ConstrainedController,
        Controller,
        ControllerLike,
        SensedController,
        load_controller,
    )
    from mitld_lp.controllers.observation import Observation, RunStatus
    from mitld_lp.distributions.fit import fit_law
    from mitld_lp.logic.constraints import Constraint, ConstraintError, parse_constraint
    from mitld_lp.logic.parser import ParseError, parse, parse_distribution
    from mitld_lp.logic.syntax import (
        FALSE,
        TRUE,
        And,
        Const,
        Dist,
        DistLiteral,
        DistRef,
        DistSpec,
        Formula,
        Interval,
        Next,
        Not,
        Or,
        Prop,
        Release,
        Until,
    )
    from mitld_lp.mdp import MDP
    from mitld_lp.model import Model, ModelError, load_model, loads_model
    from mitld_lp.problem import Problem, ProblemError, Settings
    from mitld_lp.product import ProductState, product
    from mitld_lp.result import Result, SynthesisResult
    from mitld_lp.running.simulate import simulate
    from mitld_lp.sweep import load_sweep, run_sweep
    from mitld_lp.synthesis import pose, solve, synthesize, synthesize_constrained
    from mitld_lp.tradeoff import pareto
    from mitld_lp.worlds.game import ExplicitGame, Game
    from mitld_lp.worlds.grid import GridWorld

_WHERE = {  # public name -> the module defining it, imported on first use
    "DTA": "mitld_lp.automata.dta",
    "STA": "mitld_lp.automata.sta",
    "make_sta": "mitld_lp.automata.sta",
    "to_dta": "mitld_lp.automata.translate",
    "Controller": "mitld_lp.controllers.kinds",
    "ControllerFileError": "mitld_lp.controllers.format",
    "Observation": "mitld_lp.controllers.observation",
    "RunStatus": "mitld_lp.controllers.observation",
    "ExplicitGame": "mitld_lp.worlds.game",
    "Game": "mitld_lp.worlds.game",
    "GridWorld": "mitld_lp.worlds.grid",
    "ParseError": "mitld_lp.logic.parser",
    "parse": "mitld_lp.logic.parser",
    "parse_distribution": "mitld_lp.logic.parser",
    "FALSE": "mitld_lp.logic.syntax",
    "TRUE": "mitld_lp.logic.syntax",
    "And": "mitld_lp.logic.syntax",
    "Const": "mitld_lp.logic.syntax",
    "Dist": "mitld_lp.logic.syntax",
    "DistLiteral": "mitld_lp.logic.syntax",
    "DistRef": "mitld_lp.logic.syntax",
    "DistSpec": "mitld_lp.logic.syntax",
    "Formula": "mitld_lp.logic.syntax",
    "Interval": "mitld_lp.logic.syntax",
    "Next": "mitld_lp.logic.syntax",
    "Not": "mitld_lp.logic.syntax",
    "Or": "mitld_lp.logic.syntax",
    "Prop": "mitld_lp.logic.syntax",
    "Release": "mitld_lp.logic.syntax",
    "Until": "mitld_lp.logic.syntax",
    "MDP": "mitld_lp.mdp",
    "Model": "mitld_lp.model",
    "ModelError": "mitld_lp.model",
    "load_model": "mitld_lp.model",
    "loads_model": "mitld_lp.model",
    "ProductState": "mitld_lp.product",
    "product": "mitld_lp.product",
    "simulate": "mitld_lp.running.simulate",
    "Result": "mitld_lp.result",
    "SynthesisResult": "mitld_lp.result",
    "synthesize": "mitld_lp.synthesis",
    "ConstrainedController": "mitld_lp.controllers.kinds",
    "load_controller": "mitld_lp.controllers.kinds",
    "ControllerLike": "mitld_lp.controllers.kinds",
    "SensedController": "mitld_lp.controllers.kinds",
    "solve": "mitld_lp.synthesis",
    "synthesize_constrained": "mitld_lp.synthesis",
    "pose": "mitld_lp.synthesis",
    "Problem": "mitld_lp.problem",
    "Settings": "mitld_lp.problem",
    "ProblemError": "mitld_lp.problem",
    "fit_law": "mitld_lp.distributions.fit",
    "Constraint": "mitld_lp.logic.constraints",
    "ConstraintError": "mitld_lp.logic.constraints",
    "parse_constraint": "mitld_lp.logic.constraints",
    "pareto": "mitld_lp.tradeoff",
    "run_sweep": "mitld_lp.sweep",
    "load_sweep": "mitld_lp.sweep",
}


def __getattr__(name: str) -> Any:
    """A public name, from its module on first use (PEP 562): importing the package
    (for example for :mod:`mitld_lp.runtime`) loads none of them."""
    where = _WHERE.get(name)
    if where is None:  # a submodule, as after the eager imports of old
        if not name.startswith("__") and importlib.util.find_spec(f"{__name__}.{name}"):
            return importlib.import_module(f"{__name__}.{name}")
        raise AttributeError(f"module 'mitld_lp' has no attribute {name!r}")
    value = getattr(importlib.import_module(where), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_WHERE))


class _Package(types.ModuleType):
    """The package's module type: importing the submodule ``mitld_lp.running.simulate`` (or
    ``mitld_lp.product``) does not rebind the public name ``simulate`` (``product``),
    the function, to the module, as an eager ``from ... import`` used to ensure."""

    def __setattr__(self, name: str, value: Any) -> None:
        if isinstance(value, types.ModuleType) and _WHERE.get(name, "").startswith(
                f"{__name__}.{name}"):
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package


__version__ = "0.1.0"

# One name per line so later stages can append their exports.
__all__ = [
    "__version__",
    "parse",
    "parse_distribution",
    "ParseError",
    "Formula",
    "Const",
    "Prop",
    "Not",
    "And",
    "Or",
    "Until",
    "Release",
    "Next",
    "Dist",
    "Interval",
    "DistRef",
    "DistLiteral",
    "DistSpec",
    "TRUE",
    "FALSE",
    "to_dta",
    "DTA",
    "STA",
    "make_sta",
    "Game",
    "ExplicitGame",
    "GridWorld",
    "Model",
    "ModelError",
    "load_model",
    "loads_model",
    "MDP",
    "ProductState",
    "product",
    "synthesize",
    "Result",
    "SynthesisResult",
    "Controller",
    "ControllerFileError",
    "Observation",
    "RunStatus",
    "simulate",
    "ConstrainedController",
    "ControllerLike",
    "SensedController",
    "load_controller",
    "pose",
    "solve",
    "Problem",
    "Settings",
    "ProblemError",
    "synthesize_constrained",
    "fit_law",
    "Constraint",
    "ConstraintError",
    "parse_constraint",
    "pareto",
    "run_sweep",
    "load_sweep",
]
