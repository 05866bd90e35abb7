"""Supervision of a distributed run: the launcher's supervisor of its processes, and resuming a run."""
