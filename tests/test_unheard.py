"""What each quiet agent missed of the shared table (``world.unheard``): the same entries, and
the same tick of catching up, as a set per agent updated at every quiet tick."""

from hypothesis import given, settings
from hypothesis import strategies as st

from nnql_swarm.protocol.messages import pack_updates
from nnql_swarm.world.unheard import UnheardEntries

CATCH_UP = 12
AGENTS = 3

# A tick: the entries its records changed (few distinct ones, so that most repeat), and for each
# agent whether it is quiet at that tick (not quiet: it is sent an observation).
ticks = st.lists(st.tuples(st.lists(st.integers(0, 20), max_size=9),
                           st.lists(st.booleans(), min_size=AGENTS, max_size=AGENTS)),
                 max_size=40)


@settings(max_examples=300, deadline=None)
@given(ticks)
def test_every_quiet_tick_and_every_observation_as_a_set_updated_each_tick(run):
    unheard = UnheardEntries(CATCH_UP, 21)
    plain: dict[int, set[int]] = {}  # what world.engine kept before: a set updated every tick
    for changed, quiet in run:
        updates = pack_updates(changed, [0.5] * len(changed))
        if any(quiet):
            unheard.log_tick(updates)
        for agent in range(AGENTS):
            if quiet[agent]:
                missed = plain.setdefault(agent, set())
                missed.update(changed)
                stays = len(missed) < CATCH_UP
                assert unheard.quiet(agent) == stays
                if stays:
                    continue
            assert unheard.pop(agent) == sorted(plain.pop(agent, set())), "its observation: them"


def test_an_entry_missed_twice_counts_once():
    unheard = UnheardEntries(3, 10)
    for _ in range(5):
        unheard.log_tick(pack_updates([7, 8], [1.0, 2.0]))
        assert unheard.quiet(0), "two distinct entries wait, not ten"
    unheard.log_tick(pack_updates([9], [3.0]))
    assert not unheard.quiet(0)
    assert unheard.pop(0) == [7, 8, 9]
    assert unheard.pop(0) == [], "heard"


def test_an_agent_that_leaves_the_quiet_while_others_stay_gets_only_what_it_missed():
    unheard = UnheardEntries(100, 10)
    unheard.log_tick(pack_updates([1, 2], [1.0, 2.0]))
    assert unheard.quiet(0) and unheard.quiet(1)
    unheard.log_tick(pack_updates([2, 3], [1.0, 1.0]))
    assert unheard.quiet(1)  # agent 0 is sent this tick's observation: it carries 2 and 3
    assert unheard.pop(0) == [1, 2]
    assert unheard.pop(1) == [1, 2, 3]
    unheard.log_tick(pack_updates([4], [1.0]))
    assert len(unheard._log) == 1, "nobody missed the ticks before: forgotten"
