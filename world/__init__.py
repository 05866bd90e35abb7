"""The world: grid rules, maps and scenarios (MovingAI files, generators, POGEMA's instances),
and the world process that runs the lockstep clock."""
