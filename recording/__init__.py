"""The Rerun recording of a run: sinks (files, a live viewer), the layout, merging, the experiments' curves."""
