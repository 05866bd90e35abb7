"""What the agents and the world agree on: actions, ranks, keys, messages, the run's config,
its seeded streams and its walls; how the model code runs (compiled or plain Python, ``jit``); and
what the protocol machines give whoever runs them (their effects, phases, tick traces)."""
