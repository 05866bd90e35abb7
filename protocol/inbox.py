"""The receiving end of a node: payloads decoded into messages (``protocol.messages``), every
rejection counted by reason and logged, rate-limited, never raised."""

import logging
from collections import Counter
from typing import Protocol

from nnql_swarm.protocol.keys import validate_run_id
from nnql_swarm.protocol.messages import MESSAGES, Rejected, parse

class WarningLog(Protocol):
    """Where an :class:`Inbox` logs its rejections: a ``logging.Logger``, or a protocol
    machine's log of effects."""

    def warning(self, message: str, /, *args: object) -> None: ...


class Inbox:
    """The receiving end of one node: decodes payloads, counts and logs rejections, never raises.

    ``rejections`` is a Counter of reasons, ``accepted`` the number of messages decoded. Each reason
    is logged (WARNING) for its first 10 occurrences, then every 1000th, so a flood cannot flood the
    log. Not locked: use it from one thread at a time (the nodes call it under their own lock,
    from Zenoh's callbacks and their main thread).
    """

    LOG_FIRST = 10
    LOG_EVERY = 1000

    def __init__(self, run_id: str, logger: WarningLog | None = None):
        self.run_id = validate_run_id(run_id)
        self.log = logger or logging.getLogger(__name__)
        self.rejections: Counter = Counter()
        self.accepted = 0

    @property
    def total_rejected(self) -> int:
        return sum(self.rejections.values())

    def decode(self, payload, kind: type, key_agent: int | None = None):
        """The message of class ``kind`` in ``payload``, or None (counted, logged) if rejected."""
        try:
            msg = parse(payload, kind, self.run_id, key_agent)
        except Rejected as e:
            return self.reject(e.reason, f"{kind.__name__}: {e.detail}")
        except Exception as e:  # parse raises only Rejected for any payload; this guards the loop
            if not isinstance(kind, type) or kind not in MESSAGES:  # a bug in the caller: raised
                raise
            return self.reject("decode-error", f"{kind.__name__}: {type(e).__name__}: {e}")
        self.accepted += 1
        return msg

    def reject(self, reason: str, detail: str = "") -> None:
        """Count and (rate-limited) log a rejection decided by the caller, e.g. "stale-tick"."""
        self.rejections[reason] += 1
        n = self.rejections[reason]
        if n <= self.LOG_FIRST or n % self.LOG_EVERY == 0:
            self.log.warning(
                "run %s: rejected message (%s) #%d: %.200s%s", self.run_id, reason, n, detail,
                f" (from now on every {self.LOG_EVERY}th)" if n == self.LOG_FIRST else "",
            )
        return None
