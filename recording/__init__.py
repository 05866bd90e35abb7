"""The Rerun recording of a run: the world's and each agent's logging, sinks (files, a live
viewer), the layout, merging, the experiments' curves."""
