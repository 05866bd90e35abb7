"""nnQL swarm: multi-agent Q-learning by the n-th step state over Eclipse Zenoh, logged to Rerun.

Each subpackage is one room of the repository, a top-level folder linked here (``agent/``,
``world/``, ``protocol/``...), so that installed or not, the package reads as it is imported.
"""
