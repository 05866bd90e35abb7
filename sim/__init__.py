"""Running the swarm: the simulators, the whole swarm inside one process, and the supervision of a
distributed run (the launcher's supervisor, restarts on record, resuming, whether the machine
can hold a run).

Two of them, for two questions. ``sim.episode`` (with ``sim.runs`` and ``world.pibt``) steps the
world and every agent's learner inside the compiled kernel, many seeds and options at once: the
sweeps and the experiments run on it. ``sim.distributed`` runs the very protocol machines that run
over Zenoh (``agent.agent_machine``, ``world.world_machine``) over a simulated network (``sim.network``) in
virtual time: every effect one of them produces is carried to the others with a seeded latency,
and the network injects drops, duplicates, reordering, partitions, stalls (a process that stops
answering for a while) and crashes with a restart from the last checkpoint. One seed gives one
whole history, faults included, and the same seed gives it again exactly (after FoundationDB's
deterministic simulation). ``sim.schedule`` draws a fault schedule from a seed, ``sim.checks``
holds what every history must satisfy, ``sim.parity`` what a fault-free history must equal, and
``launch/faultsim.py`` runs thousands of them.
"""
