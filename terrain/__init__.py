"""Maps and scenarios as input: MovingAI's .map and .scen files, and seeded map generators."""
