"""The adapters' shared feeding of inputs (transport.adapter), without a network: effects
carried out in order, a failing handler stopping the node, each input's cost sampled."""

import queue
import threading

from nnql_swarm.transport.adapter import CPU_SAMPLE_EVERY, ProtocolAdapter


class Node(ProtocolAdapter):
    """An adapter whose effects are strings, written down in the order they are carried out."""

    def __init__(self) -> None:
        self.lock = threading.RLock()
        self.stopping = False
        self.failure = None
        self.events = queue.SimpleQueue()
        self.handler_cpu = {}
        self.done: list[str] = []
        self._do = {str: self.done.append}

    def stop(self) -> None:
        self.stopping = True


def on_ping(tag: str, now: float) -> list[str]:
    return [f"{tag}-1", f"{tag}-2"]


def on_rare(now: float) -> list[str]:
    return ["rare"]


def test_every_input_is_carried_out_and_one_in_each_sample_is_timed():
    node = Node()
    fed = 3 * CPU_SAMPLE_EVERY + 1
    for i in range(fed):
        node.feed(on_ping, str(i))
    node.feed(on_rare)
    assert node.done == [f"{i}-{k}" for i in range(fed) for k in (1, 2)] + ["rare"]
    stats = node.handler_cpu_stats()
    assert node.handler_cpu["on_ping"][:2] == [fed, 3]
    assert stats["on_ping"]["calls"] == fed
    assert stats["on_ping"]["machine_us"] >= 0 and stats["on_ping"]["effects_us"] >= 0
    assert stats["on_rare"] == {"calls": 1, "machine_us": None, "effects_us": None}


def test_a_failing_input_stops_the_node_and_keeps_its_error_for_the_main_thread():
    node = Node()

    def on_bad(now: float) -> list[str]:
        raise ValueError("a bug")

    node.feed(on_bad)
    assert node.stopping and isinstance(node.failure, ValueError)
    node.feed(on_ping, "late")
    assert node.done == [], "a stopped node takes no more inputs"
