"""Every Zenoh key expression of the swarm, and the identifiers inside them (run ids, agent ids).

All keys live under ``nnql/<run-id>/`` so that several runs can share one Zenoh network:

- ``world/obs/<agent>``        world -> one agent: its observation of a tick
- ``world/control``            world -> everyone: control commands (shutdown)
- ``agent/<agent>/intent``     an agent's announced action (published), and the queryable that
                               answers a neighbour's ``?tick=T;from=A`` once that tick's intent is
                               decided, and a standing ``?since=T;from=A`` at every tick from T on
- ``alive/<role>/<id>``        liveliness tokens (role ``world`` or ``agent``)

Builders validate their arguments and raise ValueError (a bug on our side); parsers of what arrives
from the network (:func:`agent_from_key`, :func:`parse_intent_query`) never raise and answer None.
Agent ids are the canonical decimal form of ``0 .. MAX_AGENTS - 1``.
"""

import operator
import re

PREFIX = "nnql"
MAX_AGENTS = 1024
"""Agent ids are 0 .. MAX_AGENTS - 1 (re-exported by protocol.messages, which bounds messages)."""

RUN_ID_PATTERN = r"[A-Za-z0-9_-]{1,64}"
_RUN_ID_RE = re.compile(RUN_ID_PATTERN)
_AGENT_ID_RE = re.compile(r"0|[1-9][0-9]{0,9}")
_TICK_RE = re.compile(r"[0-9]{1,16}")
MAX_TICK = 2**53
"""Ticks (and episodes, steps) are 0 .. MAX_TICK - 1: exact in every JSON/float consumer."""

ROLE_WORLD = "world"
ROLE_AGENT = "agent"
ROLES = frozenset({ROLE_WORLD, ROLE_AGENT})

INTENT_QUERY_TICK = "tick"
"""Selector parameter of an intent query: ``nnql/<run>/agent/<id>/intent?tick=12;from=3``."""
INTENT_QUERY_ASKER = "from"
"""Selector parameter naming the asking agent, so that answers go out in negotiation order."""
INTENT_QUERY_SINCE = "since"
"""Selector parameter of a standing intent query, answered at every tick from this one on:
``nnql/<run>/agent/<id>/intent?since=12;from=3``."""


def validate_run_id(run_id: str) -> str:
    """``run_id`` if it is a valid run id (one key chunk, no wildcards), else raise ValueError."""
    if not isinstance(run_id, str) or not _RUN_ID_RE.fullmatch(run_id):
        raise ValueError(
            f"invalid run id {run_id!r}: use 1 to 64 characters from A-Z a-z 0-9 _ - "
            f"(pattern {RUN_ID_PATTERN})"
        )
    return run_id


def validate_agent(agent: int) -> int:
    """``agent`` as an int if it is a valid agent id (numpy ints too), else raise ValueError."""
    try:
        if isinstance(agent, bool):
            raise TypeError
        value = operator.index(agent)
    except TypeError:
        raise ValueError(f"invalid agent id {agent!r}: expected an int") from None
    if not 0 <= value < MAX_AGENTS:
        raise ValueError(f"invalid agent id {value}: expected 0 .. {MAX_AGENTS - 1}")
    return value


def _run(run_id: str) -> str:
    return f"{PREFIX}/{validate_run_id(run_id)}"


def obs_key(run_id: str, agent: int) -> str:
    """``nnql/<run>/world/obs/<agent>``: the world's observation for one agent."""
    return f"{_run(run_id)}/world/obs/{validate_agent(agent)}"


def intent_key(run_id: str, agent: int) -> str:
    """``nnql/<run>/agent/<agent>/intent``: published intents; its queryable answers ``?tick=T``."""
    return f"{_run(run_id)}/agent/{validate_agent(agent)}/intent"


def intent_key_all(run_id: str) -> str:
    """``nnql/<run>/agent/*/intent``: every agent's intents (the world subscribes to it)."""
    return f"{_run(run_id)}/agent/*/intent"


def control_key(run_id: str) -> str:
    """``nnql/<run>/world/control``: control commands from the world."""
    return f"{_run(run_id)}/world/control"


def alive_key(run_id: str, role: str, ident) -> str:
    """``nnql/<run>/alive/<role>/<id>``: a liveliness token (an agent's id is its agent id)."""
    if role not in ROLES:
        raise ValueError(f"invalid role {role!r}: expected one of {sorted(ROLES)}")
    if role == ROLE_AGENT:
        ident = validate_agent(ident)
    elif isinstance(ident, bool) or not _RUN_ID_RE.fullmatch(str(ident)):
        raise ValueError(f"invalid {role} id {ident!r}: expected pattern {RUN_ID_PATTERN}")
    return f"{_run(run_id)}/alive/{role}/{ident}"


def alive_key_all(run_id: str, role: str) -> str:
    """``nnql/<run>/alive/<role>/*``: every liveliness token of one role."""
    if role not in ROLES:
        raise ValueError(f"invalid role {role!r}: expected one of {sorted(ROLES)}")
    return f"{_run(run_id)}/alive/{role}/*"


def agent_from_key(key, run_id: str) -> int | None:
    """The agent id in an intent key or an ``alive/agent/<id>`` key of this run, else None.

    Accepts a str or anything whose ``str()`` is the key (zenoh's KeyExpr). Never raises.
    """
    try:
        parts = str(key).split("/")
    except Exception:
        return None
    if len(parts) != 5 or parts[0] != PREFIX or parts[1] != run_id:
        return None
    if parts[2] == "agent" and parts[4] == "intent":
        ident = parts[3]
    elif parts[2] == "alive" and parts[3] == ROLE_AGENT:
        ident = parts[4]
    else:
        return None
    if not _AGENT_ID_RE.fullmatch(ident):
        return None
    agent = int(ident)
    return agent if agent < MAX_AGENTS else None


def intent_query_params(tick: int, asker: int | None = None) -> str:
    """The selector parameters asking for one tick's intent: ``"tick=12;from=3"``."""
    if isinstance(tick, bool):
        raise ValueError(f"invalid tick {tick!r}")
    tick = operator.index(tick)
    if not 0 <= tick < MAX_TICK:
        raise ValueError(f"invalid tick {tick}: expected 0 .. 2**53 - 1")
    if asker is None:
        return f"{INTENT_QUERY_TICK}={tick}"
    return f"{INTENT_QUERY_TICK}={tick};{INTENT_QUERY_ASKER}={validate_agent(asker)}"


def standing_query_params(since: int, asker: int) -> str:
    """The selector parameters of a standing query: ``"since=12;from=3"``."""
    return (f"{INTENT_QUERY_SINCE}={intent_query_params(since).partition('=')[2]};"
            f"{INTENT_QUERY_ASKER}={validate_agent(asker)}")


def _param_from_str(text: str, name: str):
    for part in text.removeprefix("?").split(";"):
        key, _, value = part.partition("=")
        if key == name:
            return value
    return None


def parse_intent_asker(parameters) -> int | None:
    """The asking agent named by an intent query, or None if absent or malformed. Never raises.

    The asker only orders the answers (the next in rank first); nothing trusts it beyond that.
    """
    value = _param(parameters, INTENT_QUERY_ASKER)
    if not isinstance(value, str) or not _AGENT_ID_RE.fullmatch(value):
        return None
    agent = int(value)
    return agent if agent < MAX_AGENTS else None


def parse_intent_query(parameters) -> int | None:
    """The tick asked for by an intent query, or None if missing, malformed, negative or huge.

    ``parameters`` is zenoh's ``Parameters`` (``query.parameters``), a str such as ``"tick=12"``
    (``;``-separated, as zenoh writes them) or a dict-like. Never raises.
    """
    return _tick_param(parameters, INTENT_QUERY_TICK)


def parse_standing_since(parameters) -> int | None:
    """The first tick of a standing query (``since``), or None as :func:`parse_intent_query`."""
    return _tick_param(parameters, INTENT_QUERY_SINCE)


def _param(parameters, name: str):
    """The raw value of one selector parameter (str, dict-like or zenoh's), or None. Never raises."""
    try:
        if isinstance(parameters, str):
            return _param_from_str(parameters, name)
        return None if parameters is None else parameters.get(name)
    except Exception:
        return None


def _tick_param(parameters, name: str) -> int | None:
    value = _param(parameters, name)
    if type(value) is int:
        tick = value
    elif isinstance(value, str) and _TICK_RE.fullmatch(value):
        tick = int(value)
    else:
        return None
    return tick if 0 <= tick < MAX_TICK else None
