"""Zenoh for every process of a run: session settings, runtime, handlers, ports, topologies."""
