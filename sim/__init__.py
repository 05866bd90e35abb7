"""A deterministic simulation of the swarm in one process, in virtual time, with faults.

The same protocol machines that run over Zenoh (``agent.protocol``, ``world.protocol``) run here
over a simulated network (``sim.network``): every effect one of them produces is carried to the
others with a seeded latency, and the network injects drops, duplicates, reordering,
partitions, stalls (a process that stops answering for a while) and crashes with a restart from
the last checkpoint. One seed gives one whole history, faults included, and the same seed gives
it again exactly (after FoundationDB's deterministic simulation). ``sim.schedule`` draws a fault
schedule from a seed, ``sim.distributed`` runs it, ``sim.checks`` holds what every history must
satisfy, and ``launch/faultsim.py`` runs thousands of them.
"""
