"""Entry points that wire agents and world together: the swarm launcher and the paper's experiment."""
