"""Learning, the ground the agents and the world share: the learner's kernel (Eq. 6-10), its
buffers, its readings of its neighbours and its known map, learning records, saved tables.

An agent learns with it; the world checks and applies the agents' learning records with the same
code; the simulator runs it compiled. It imports only ``protocol``, and neither ``agent`` nor
``world`` imports the other: both import this."""
