"""The one-machine topologies: who listens, who connects, in which Zenoh mode.

The world (or a router process) is the hub and listens on a free loopback port; everyone else
joins through it (:class:`EmbeddedLayout`). In the ``mesh`` agents are peers that also listen,
and gossip scouting joins them into a full mesh; in the hub topologies they are clients of the
hub (or peers without gossip, ``star-peers``); ``router`` puts a router process in the middle.
"""

from dataclasses import dataclass, field

from nnql_swarm.transport.ports import free_port
from nnql_swarm.transport.settings import TransportSettings

TOPOLOGIES = ("mesh", "hub-peer", "hub-router", "router", "star-peers")

HUB_FROM_AGENTS = 32
"""From this many agents the launcher's embedded layout is ``hub-peer`` rather than ``mesh``
(:func:`embedded_topology`): from about this size the mesh's links (one per pair of agents)
cost each agent memory and start-up time, and the hub ticks at least as fast; figures with
their command (``bench/scale.py --topology``): docs/performance.md."""

HUB_CONNECT_S = 60.0
"""How long an agent that is a client of the hub keeps retrying its connect: many agents that
connect at once to a world still starting up on a busy machine are refused, and a Zenoh client
by default does not retry."""


REJOIN_DEAF_S = 30.0
"""How long an agent that is a client of the world as hub may hear no other agent before it
opens its session again (``TransportSettings.rejoin_deaf_s``): of 512 agents joining at once on
two cores, a few in each run were heard by nobody and heard nobody, for good (Zenoh 1.10 lost
their declarations at the hub; docs/performance.md, "At scale")."""


def embedded_topology(n_agents: int) -> str:
    """The launcher's one-machine topology for a swarm of ``n_agents``."""
    return "hub-peer" if n_agents >= HUB_FROM_AGENTS else "mesh"


@dataclass(frozen=True)
class EmbeddedLayout:
    """The one-machine layout: the hub (the world, or a router process) listens on ``port``;
    everyone else joins through it, as ``topology`` says."""

    port: int = field(default_factory=free_port)
    host: str = "127.0.0.1"
    topology: str = "mesh"

    def __post_init__(self) -> None:
        if self.topology not in TOPOLOGIES:
            raise ValueError(f"topology must be one of {', '.join(TOPOLOGIES)}")

    @property
    def endpoint(self) -> str:
        return f"tcp/{self.host}:{self.port}"

    def router(self) -> TransportSettings | None:
        """The router process's settings, where the topology has one."""
        if self.topology != "router":
            return None
        return TransportSettings(mode="router", listen=(self.endpoint,), gossip=False)

    def world(self) -> TransportSettings:
        t = self.topology
        if t == "router":
            return TransportSettings(mode="client", connect=(self.endpoint,))
        mode = "router" if t in ("hub-router", "star-peers") else "peer"
        return TransportSettings(mode=mode, listen=(self.endpoint,),
                                 gossip=None if t == "mesh" else False)

    @property
    def agents_wait_for_hub(self) -> bool:
        """Whether agents must wait for the hub to listen (clients: not in the mesh)."""
        return self.topology not in ("mesh", "star-peers")

    def agent(self) -> TransportSettings:
        t = self.topology
        if t == "mesh":
            return TransportSettings(mode="peer", listen=(f"tcp/{self.host}:0",),
                                     connect=(self.endpoint,))
        if t == "star-peers":
            return TransportSettings(mode="peer", connect=(self.endpoint,), gossip=False)
        return TransportSettings(mode="client", connect=(self.endpoint,),
                                 connect_timeout_s=HUB_CONNECT_S,
                                 rejoin_deaf_s=0.0 if t == "router" else REJOIN_DEAF_S)
