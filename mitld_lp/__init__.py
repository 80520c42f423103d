"""mitld_lp: policy synthesis for MITLD (Metric Interval Temporal Logic with distribution
eventualities) by occupancy-measure linear programming.

``import mitld_lp`` loads no solver stack (cvxpy, Clarabel, HiGHS, scipy's linear
algebra, ``mitld_lp.solvers``): :func:`synthesize` imports it at its first solve
(tests/test_imports.py checks this in a fresh interpreter).
"""

from mitld_lp import startup  # noqa: F401 - first: Ctrl-C while the command line imports
from mitld_lp.automata.dta import DTA
from mitld_lp.automata.sta import STA, make_sta
from mitld_lp.automata.translate import to_dta
from mitld_lp.controller import Controller, ControllerFileError, Observation, RunStatus
from mitld_lp.game import ExplicitGame, Game
from mitld_lp.gridworld import GridWorld
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
from mitld_lp.problem import Problem, ProblemError, Settings, pose
from mitld_lp.product import ProductState, product
from mitld_lp.simulate import simulate
from mitld_lp.synthesis import SynthesisResult, solve, synthesize, synthesize_constrained

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
    "SynthesisResult",
    "Controller",
    "ControllerFileError",
    "Observation",
    "RunStatus",
    "simulate",
    "pose",
    "solve",
    "Problem",
    "Settings",
    "ProblemError",
    "fit_law",
    "synthesize_constrained",
    "run_sweep",
    "load_sweep",
]

#: Names whose modules pull in the solver stack or optional packages: imported on first
#: use, so that ``import mitld_lp`` stays light (tests/test_imports.py).  (The sweep
#: and pareto functions keep their modules' names, ``mitld_lp.sweep.sweep`` and
#: ``mitld_lp.pareto.pareto``: a package attribute cannot be both.)
_LAZY = {
    "fit_law": "mitld_lp.distributions.fit",
    "run_sweep": "mitld_lp.sweep",
    "load_sweep": "mitld_lp.sweep",
}


def __getattr__(name: str) -> object:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'mitld_lp' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value
