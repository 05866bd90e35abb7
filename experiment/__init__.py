"""The experiments: the paper's Table 1 and the swarm's variants, their tables and figures."""
