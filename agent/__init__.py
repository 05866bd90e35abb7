"""The agent: one agent's decisions, whom it asks for intents, its checkpoints, its negotiation as
a pure state machine, and the agent process that runs them over Zenoh (the learner is in
``learning``)."""
