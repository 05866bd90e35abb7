"""I/O for every process of a run: Zenoh (session settings, runtime, handlers, ports,
topologies) and the run folder's files (its layout and atomic writes, its lock, the checkpoints'
slot files)."""
