"""What the agents and the world agree on: actions, ranks, keys, messages, the run's config,
its seeded streams and its walls."""
