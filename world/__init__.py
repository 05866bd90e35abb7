"""The world: grid rules, scenarios and the world process that runs the lockstep clock."""
