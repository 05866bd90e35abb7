#!/usr/bin/env python3
"""Delay, jitter and reordering of a network namespace's packets in user space, for kernels
without netem (``sch_netem``): iptables hands each packet of ``eth0`` to an NFQUEUE, this program
holds it and lets it go on after its delay.

    ip netns exec HOST python tests/netdelay.py --delay-ms 5 --jitter-ms 2 --reorder 0.25

Each packet, in or out, is held for ``delay ± jitter`` ms (drawn uniformly),
except a ``--reorder`` share let through at once, as netem's ``reorder``; packets whose delays
cross overtake each other. The iptables rules (``-i eth0`` and ``-o eth0`` to queue
``--queue``, with ``--queue-bypass``: packets pass unheld when nobody listens) are added by
:meth:`tests.netns.Lan.delay`, not here. Prints ``ready`` once bound to the queue; runs until
SIGTERM, then lets every held packet go and prints ``held N packets`` (``--probe``: binds, prints
``ready`` and exits). The nfnetlink_queue protocol is spoken directly over a netlink socket.
"""

import argparse
import heapq
import random
import select
import signal
import socket
import struct
import sys
import time

NETLINK_NETFILTER = 12
NFNL_SUBSYS_QUEUE = 3
NFQNL_MSG_PACKET, NFQNL_MSG_VERDICT, NFQNL_MSG_CONFIG = 0, 1, 2
NFQA_CFG_CMD, NFQA_CFG_PARAMS = 1, 2
NFQA_PACKET_HDR, NFQA_VERDICT_HDR = 1, 2
NFQNL_CFG_CMD_BIND = 1
NFQNL_COPY_META = 1
NF_ACCEPT = 1
NLM_F_REQUEST, NLM_F_ACK = 1, 4
NLMSG_ERROR = 2


def attribute(kind: int, payload: bytes) -> bytes:
    length = 4 + len(payload)
    return struct.pack("=HH", length, kind) + payload + b"\0" * (-length % 4)


def message(kind: int, queue: int, attributes: bytes, flags: int = NLM_F_REQUEST,
            seq: int = 0) -> bytes:
    body = struct.pack("=BBH", socket.AF_UNSPEC, 0, socket.htons(queue)) + attributes
    return struct.pack("=IHHII", 16 + len(body), (NFNL_SUBSYS_QUEUE << 8) | kind, flags, seq,
                       0) + body


def attributes(data: bytes) -> dict[int, bytes]:
    found, offset = {}, 0
    while offset + 4 <= len(data):
        length, kind = struct.unpack_from("=HH", data, offset)
        if length < 4:
            break
        found[kind & 0x3FFF] = data[offset + 4:offset + length]
        offset += (length + 3) & ~3
    return found


class Queue:
    """One bound NFQUEUE: packets in, verdicts out."""

    def __init__(self, number: int) -> None:
        self.number = number
        self.sock = socket.socket(socket.AF_NETLINK, socket.SOCK_RAW, NETLINK_NETFILTER)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
        self.sock.bind((0, 0))
        self._request(attribute(NFQA_CFG_CMD, struct.pack("=BBH", NFQNL_CFG_CMD_BIND, 0, 0)), 1)
        self._request(attribute(NFQA_CFG_PARAMS, struct.pack("!IB", 0, NFQNL_COPY_META)), 2)

    def _request(self, attrs: bytes, seq: int) -> None:
        self.sock.send(message(NFQNL_MSG_CONFIG, self.number, attrs, NLM_F_REQUEST | NLM_F_ACK,
                               seq))
        reply = self.sock.recv(65536)
        length, kind = struct.unpack_from("=IH", reply)
        if kind == NLMSG_ERROR:
            error = struct.unpack_from("=i", reply, 16)[0]
            if error:
                raise OSError(-error, f"nfnetlink_queue refused the config: "
                                      f"{socket.errno.errorcode.get(-error, error)}")

    def packets(self) -> list[int]:
        """The ids of the packets waiting in one read of the socket."""
        data = self.sock.recv(1 << 20)
        ids, offset = [], 0
        while offset + 16 <= len(data):
            length, kind = struct.unpack_from("=IH", data, offset)
            if length < 16:
                break
            if kind == (NFNL_SUBSYS_QUEUE << 8) | NFQNL_MSG_PACKET:
                header = attributes(data[offset + 20:offset + length]).get(NFQA_PACKET_HDR)
                if header:
                    ids.append(struct.unpack_from("!I", header)[0])
            offset += (length + 3) & ~3
        return ids

    def accept(self, packet: int) -> None:
        self.sock.send(message(NFQNL_MSG_VERDICT, self.number,
                               attribute(NFQA_VERDICT_HDR, struct.pack("!II", NF_ACCEPT, packet))))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--queue", type=int, default=0)
    p.add_argument("--delay-ms", type=float, default=5.0)
    p.add_argument("--jitter-ms", type=float, default=2.0)
    p.add_argument("--reorder", type=float, default=0.0, help="share of packets sent at once")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--probe", action="store_true", help="bind, print ready, exit")
    args = p.parse_args()
    queue = Queue(args.queue)
    print("ready", flush=True)
    if args.probe:
        return 0
    draw = random.Random(args.seed)
    stopping = []
    signal.signal(signal.SIGTERM, lambda *_: stopping.append(True))
    held: list[tuple[float, int, int]] = []  # (release time, order, packet id)
    order = count = 0
    while not stopping:
        now = time.monotonic()
        while held and held[0][0] <= now:
            queue.accept(heapq.heappop(held)[2])
        wait = max(0.0, held[0][0] - now) if held else 0.5
        try:
            readable, _, _ = select.select([queue.sock], [], [], wait)
        except InterruptedError:
            continue
        if not readable:
            continue
        now = time.monotonic()
        for packet in queue.packets():
            count += 1
            if draw.random() < args.reorder:
                queue.accept(packet)
                continue
            delay = args.delay_ms + draw.uniform(-args.jitter_ms, args.jitter_ms)
            order += 1
            heapq.heappush(held, (now + max(0.0, delay) / 1000, order, packet))
    while held:
        queue.accept(heapq.heappop(held)[2])
    print(f"held {count} packets", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
