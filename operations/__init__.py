"""Zenoh operations: config files per process, a router, and a secured deployment's certificates."""
