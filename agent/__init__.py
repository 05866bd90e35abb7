"""The agent: the nnQL / QL learning core and the agent process that runs it over Zenoh."""
