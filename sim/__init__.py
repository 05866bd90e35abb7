"""Simulators: the whole swarm inside one process."""
