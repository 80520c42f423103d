"""A synthesised controller acting in a gymnasium environment itself (the world read
from its transition table by :mod:`mitld_lp.worlds.gym`)."""

from __future__ import annotations

from typing import Any

from mitld_lp.controllers.observation import Observation
from mitld_lp.worlds.gym import GymGame

__all__ = ["GymAgent"]


class GymAgent:
    """A controller of a :class:`~mitld_lp.worlds.gym.GymGame` acting in the environment itself::

        agent = GymAgent(result.controller, game)
        obs, _ = env.reset(seed=1)
        action = agent.reset(obs)
        while action is not None:
            obs, reward, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                break
            action = agent.step(obs, reward, terminated)

    It keeps the step count and the propositions of the last transition, gives the
    controller the game's state and returns the environment's action (an integer for
    toy-text environments); ``None`` once the task is decided.  ``agent.controller``
    tells the run's status.
    """

    def __init__(self, controller: Any, game: GymGame) -> None:
        if not isinstance(game, GymGame):
            raise TypeError(f"GymAgent: game must be a GymGame (from_env), got "
                            f"{type(game).__name__}")
        self.controller, self.game, self.t = controller, game, 0

    def _act(self, state: Any) -> Any:
        name = self.controller.act(Observation(state))
        return None if name is None else self.game.env_actions.get(name, name)

    def reset(self, observation: Any) -> Any:
        """The first action, in the environment's ``observation`` after ``env.reset``."""
        self.controller.reset()
        self.t = 0
        return self._act(self.game.state_of(observation))

    def step(self, observation: Any, reward: float = 0.0, terminated: bool = False) -> Any:
        """The next action, after ``env.step`` returned ``observation``, ``reward`` and
        ``terminated``."""
        self.t += 1
        entered = self.game.entered(reward, terminated)
        return self._act(self.game.state_of(observation, self.t, entered, terminated))
