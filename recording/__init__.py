"""The Rerun recording of a run: sinks, viewers, the layout, merging, the experiments' curves."""
