"""What a run's first view has to show, from its config alone: the blueprint
(``recording.blueprint``) leaves out a panel that has nothing to show under the run's preset,
and the agents do not log what no panel shows.

- An oracle (``--algo oracle``) plans and learns nothing: no heat maps, no exploration curve.
- ``Q_CA`` learns nothing where negotiating agents keep the shield (``--shield``: they never
  move into a cell a neighbour announced, so they hardly ever collide) and the table starts at
  the value of never colliding (``--optimistic`` at :func:`collision_bound`, e.g. 25): every
  update then gives back the same value. That is the default preset (``path-nnql``) and
  ``shield-nnql``; the picture would read "nothing learned yet" for the whole run.
- Only negotiating algorithms (``nnql``, ``nnql-dir``) wait for anyone: the other presets have
  no waits to plot, and their agents no negotiation wait to time.
"""

from nnql_swarm.protocol.config import NEGOTIATING_ALGOS, SwarmConfig


def collision_bound(config: SwarmConfig) -> float:
    """The largest value Q_CA can learn: the no-collision reward (10) every step, discounted."""
    return 10.0 / (1.0 - config.gamma)


def learns(config: SwarmConfig) -> bool:
    """Whether the run's agents have Q-tables that learn (not an oracle's plans)."""
    return config.algo != "oracle"


def ca_learns(config: SwarmConfig) -> bool:
    """Whether Q_CA can move off its initial value in this run (see the module's text)."""
    kept_apart = config.shield and config.algo in NEGOTIATING_ALGOS
    return learns(config) and not (kept_apart and config.optimistic >= collision_bound(config))


def negotiates(config: SwarmConfig) -> bool:
    """Whether the agents wait for their neighbours' intents (the waits, the negotiation wait)."""
    return config.algo in NEGOTIATING_ALGOS
