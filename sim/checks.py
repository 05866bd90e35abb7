"""What every simulated history must satisfy, checked as it happens and at its end.

- After every tick, no two agents share a cell, nobody jumps more than one cell, and, where swaps
  count, no two agents pass through each other: read from the observations the world sends (all
  of a tick's at once), tick after tick of one episode of one world. The world sends every agent
  its observation, but for quiet ones (``world.engine``): an agent it was last sent an arrived
  observation of the episode for, which stays where it was.
- No announced intent changes: within one world's life (a world restarted with ``--resume``
  replays tick numbers), every word on agent ``j``'s intent at tick ``t`` (its intent to the
  world, its answers, and the relays of it in others' answers) says the same action; and an
  agent announces only ticks it was sent an observation for.
- Every episode is in the metrics exactly once, in order, and the run's ends are in order.
- An agent restarted after a crash holds exactly its last checkpoint's tables, and that
  checkpoint holds every episode whose end the world heard from it; after everyone was killed,
  every agent holds its tables of the run's cut.
- The run ends: the world completes, and every agent still running stops.
- The shared table believes no forged learning record: the world applies none of those a
  compromised agent sent (the ``forge`` fault), and refuses as forged only those (or intents an
  agent decided for the world before a resumed one, which replays tick numbers: such an intent
  describes a transition the new world never saw)
  (``world.records``).
"""

from nnql_swarm.protocol.config import SwarmConfig


class Checker:
    """Collects the failures of one simulated run (``failures``, empty if none)."""

    def __init__(self, config: SwarmConfig) -> None:
        self.n = config.n_agents
        self.width, self.height = config.width, config.height
        self.count_swaps = config.count_swaps
        self.failures: list[str] = []
        self._last: dict[int, tuple] = {}  # world era -> (tick, episode, cells)
        self._arrived: dict[int, dict[int, bool]] = {}  # era -> agent -> its last one arrived
        self._sent_in: list[dict[int, int]] = [{} for _ in range(self.n)]  # agent: tick -> era
        self._said: dict[tuple[int, int, int], tuple[int, str]] = {}
        self._ends_heard = [-1] * self.n  # per agent: the last episode whose end the world heard
        self._forged: dict[tuple[int | None, int, int], tuple] = {}  # (era, tick, agent) -> its record
        self._stale: set[tuple[int, int, int]] = set()  # intents decided for an earlier world

    def fail(self, message: str) -> None:
        if len(self.failures) < 20:
            self.failures.append(message)

    def tick_sent(self, era: int, observations: list) -> None:
        """One tick's observations, as world number ``era`` sends them."""
        first = observations[0]
        tick, episode = first.tick, first.episode
        sent: list[tuple[int, int] | None] = [None] * self.n
        for obs in observations:
            sent[obs.agent] = obs.position
        last = self._last.get(era)
        arrived = self._arrived.setdefault(era, {})
        for i, cell in enumerate(sent):
            if cell is None and last is not None and last[1] == episode and arrived.get(i):
                sent[i] = last[2][i]  # quiet: it stays on its goal
        cells = [cell for cell in sent if cell is not None]
        if len(cells) < self.n or len(observations) != len({obs.agent for obs in observations}):
            self.fail(f"tick {tick}: the world sent {len(observations)} observations")
            return
        for obs in observations:
            arrived[obs.agent] = obs.arrived and not obs.episode_end
        if len(set(cells)) != self.n:
            shared = sorted({c for c in cells if cells.count(c) > 1})
            self.fail(f"tick {tick}: two agents share a cell {shared}")
        if any(not (0 <= x < self.width and 0 <= y < self.height) for x, y in cells):
            self.fail(f"tick {tick}: an agent is off the grid: {cells}")
        if last is not None and last[0] == tick - 1 and last[1] == episode:
            before = last[2]
            was_at = {cell: i for i, cell in enumerate(before)}
            for i, (cell, old) in enumerate(zip(cells, before)):
                if abs(cell[0] - old[0]) + abs(cell[1] - old[1]) > 1:
                    self.fail(f"tick {tick - 1}: agent {i} jumped from {old} to {cell}")
                elif self.count_swaps and cell != old:
                    j = was_at.get(cell)
                    if j is not None and j > i and cells[j] == old:
                        self.fail(f"tick {tick - 1}: agents {i} and {j} swapped through each other")
        self._last[era] = (tick, episode, cells)

    def observation_in(self, agent: int, era: int, tick: int) -> None:
        """Agent ``agent`` was handed world ``era``'s observation of ``tick``."""
        self._sent_in[agent][tick] = era

    def announced(self, agent: int, tick: int, action: int, relayed, what: str) -> None:
        """Agent ``agent`` said its action at ``tick`` (``what``: its intent, or an answer
        relaying ``relayed``)."""
        era = self._sent_in[agent].get(tick)
        if era is None:
            self.fail(f"agent {agent} announced tick {tick}, which it was never sent")
            return
        self._say(era, tick, agent, action, f"agent {agent}'s {what}")
        for other, other_action in relayed:
            self._say(era, tick, other, other_action, f"agent {agent}'s relay")

    def _say(self, era: int, tick: int, agent: int, action: int, source: str) -> None:
        key = (era, tick, agent)
        known = self._said.get(key)
        if known is None:
            self._said[key] = (action, source)
        elif known[0] != action:
            self.fail(f"tick {tick}: agent {agent}'s intent changed: {known[0]} ({known[1]}), "
                      f"then {action} ({source})")

    def forged(self, agent: int, tick: int, record: tuple) -> None:
        """Agent ``agent``'s intent of ``tick`` carries the forged ``record``."""
        era = self._sent_in[agent].get(tick)
        self._forged[(era, tick, agent)] = record

    def records_applied(self, era: int, tick: int, records: dict) -> None:
        """World ``era`` applied ``records`` (by agent) of ``tick`` to the shared table."""
        for agent, record in records.items():
            if self._forged.get((era, tick, agent)) == record:
                self.fail(f"tick {tick}: the world applied agent {agent}'s forged record")

    def era_of(self, agent: int, tick: int) -> int | None:
        """The world whose observation of ``tick`` agent ``agent`` answers."""
        return self._sent_in[agent].get(tick)

    def stale_intent(self, era: int, agent: int, tick: int) -> None:
        """World ``era`` was handed agent ``agent``'s intent of ``tick`` decided for the world
        before it: its record describes a transition this world never saw, and the world may
        refuse it."""
        self._stale.add((era, tick, agent))

    def forgeries_refused(self, era: int, refused) -> None:
        """World ``era`` refused as forged the records ``(agent, tick)`` of ``refused``."""
        for agent, tick in refused:
            if (era, tick, agent) not in self._forged and (era, tick, agent) not in self._stale:
                self.fail(f"tick {tick}: the world refused agent {agent}'s honest record as forged")

    def end_heard(self, episode: int, missed) -> None:
        """The world applied an episode's end tick; ``missed``: whose intents it lacked."""
        for agent in range(self.n):
            if agent not in missed:
                self._ends_heard[agent] = max(self._ends_heard[agent], episode)

    def rewound(self, cut: int) -> None:
        """The run was resumed after episode ``cut``: the world hears every end again."""
        self._ends_heard = [min(heard, cut) for heard in self._ends_heard]

    def restarted(self, agent: int, resumed: dict | None, saved: tuple[int, str] | None) -> None:
        """Agent ``agent`` came back as ``resumed`` (episode and tables, or None for a fresh
        brain); ``saved`` is its last checkpoint as it was written (episode, tables)."""
        got = None if resumed is None else (resumed["episode"], resumed["fingerprint"])
        if got != saved:
            self.fail(f"agent {agent} restarted with {got}, its last checkpoint was {saved}")
        heard = self._ends_heard[agent]
        if heard >= 0 and (got is None or got[0] < heard):
            self.fail(f"agent {agent} restarted from episode {None if got is None else got[0]}, "
                      f"but the world heard its end of episode {heard}")

    def metrics(self, rows: list[dict], episodes: int) -> None:
        """The run's ``episodes.csv`` rows."""
        numbers = [row["episode"] for row in rows]
        if numbers != list(range(episodes)):
            self.fail(f"the metrics hold episodes {numbers}, not 0..{episodes - 1} once each")
        ends = [row["end_tick"] for row in rows]
        if ends != sorted(set(ends)):
            self.fail(f"the episodes' end ticks are out of order: {ends}")
