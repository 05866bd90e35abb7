"""What the agents and the world share: the action set, the egocentric window, keys and messages."""
