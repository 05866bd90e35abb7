"""Files on disk: a run directory's layout, atomic writes, and the checkpoints' slot files."""
