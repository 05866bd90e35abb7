"""One learner's tables and state as the learner kernel's buffers (``learning.learner``): what
an agent learns with, and what the world keeps the swarm's shared table in
(``world.shared_table``)."""

import numpy as np

from nnql_swarm.learning.fields import (
    LF_FIELDS, LS_PENDING, LS_TAKEN, READINGS, REC_COUNT, REC_PAIRS, RF_FIELDS, LearnerBuffers,
    VALUES_SIZE, ca_rows, learner_params, record_size, state_size,
)
from nnql_swarm.learning.known_map import fresh_map, known_cells, map_size, restore_known
from nnql_swarm.protocol.actions import N_ACTIONS, N_STATES
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.protocol.jit import COMPILED, python_values


class Learner:
    """One agent's tables and learner state as the kernel's buffers.

    The two tables are views of one array, ``Q_DS``'s rows first (:attr:`entries`, flat, is how
    a shared table's updates name its Q-values), a numpy array whether the kernel is compiled or
    not (``protocol.jit``); the other buffers are arrays too where ``arrays`` (by default, where
    the kernel is compiled; in an agent that decides ahead of time, ``learning.ahead``), else Python
    lists. Among them are the walls it has seen and its way to its goal (``wmap``,
    ``learning.known_map``), which the agent derives from the run's map (``config.walls()``) and
    its own positions: the world sends no walls."""

    def __init__(self, config: SwarmConfig, arrays: bool = COMPILED) -> None:
        reading = READINGS[config.algo]
        params, params_f = learner_params(config)
        ints, floats, _ = buffer_makers(arrays)
        self.params, self.params_f = ints(params), floats(params_f)
        both = np.full((N_STATES + ca_rows(reading, config.known_state), N_ACTIONS),
                       float(config.optimistic))
        self.q_ds, self.q_ca = both[:N_STATES], both[N_STATES:]
        self.entries = both.reshape(-1)  # entry e: row e // N_ACTIONS, action e % N_ACTIONS
        self.state = ints([0] * state_size(config.n_bodies))
        self.state_f = floats([0.0] * LF_FIELDS)
        self.rec = ints([0] * record_size(config.n_bodies))
        self.rec_f = floats([0.0] * RF_FIELDS)
        self.values = floats([0.0] * VALUES_SIZE)
        self.width, self.height = config.width, config.height
        self.wmap = ints([0] * map_size(config.width, config.height))
        fresh_map(self.wmap)
        self.buffers = LearnerBuffers(self.q_ds, self.q_ca, self.params, self.params_f,
                                      self.state, self.state_f, self.wmap, self.rec, self.rec_f,
                                      self.values)
        """The same buffers as the learner's kernel takes them (``learning.learner``)."""

    @property
    def actions_taken(self) -> int:
        return int(self.state[LS_TAKEN])

    def tables(self) -> tuple[np.ndarray, np.ndarray]:
        """``Q_DS`` and ``Q_CA`` as arrays (copies), for checkpoints and pictures."""
        return self.q_ds.copy(), self.q_ca.copy()

    def known_walls(self) -> list[int]:
        """The cells (``y * W + x``) of the walls this learner has seen (``learning.known_map``)."""
        return known_cells(self.wmap, self.width, self.height)

    def restore(self, q_ds: np.ndarray, q_ca: np.ndarray, actions_taken: int,
                known_walls=()) -> None:
        """Take the tables, count and known walls of a checkpoint (shapes checked by the
        caller)."""
        self.q_ds[:], self.q_ca[:] = q_ds, q_ca
        self.state[LS_TAKEN] = int(actions_taken)
        restore_known(self.wmap, [int(c) for c in known_walls], self.width, self.height)

    def forget_pending(self) -> None:
        """Drop the pending transition (its episode was abandoned, e.g. the world restarted)."""
        self.state[LS_PENDING] = 0

    def record(self) -> tuple[tuple[int, ...], tuple[float, float]]:
        """The learning record just written, as it travels: its integers and its two rewards."""
        rec = self.rec
        written = python_values(rec[:REC_PAIRS + 2 * int(rec[REC_COUNT])])
        return tuple(written), tuple(python_values(self.rec_f))


def int_array(values) -> np.ndarray:
    return np.array(values, dtype=np.int64)


def float_array(values) -> np.ndarray:
    return np.array(values, dtype=np.float64)


def flag_array(values) -> np.ndarray:
    return np.array(values, dtype=np.bool_)


def buffer_makers(arrays: bool) -> tuple:
    """How kernel buffers are made from values, integers, floats and flags: numpy arrays where
    the kernels are compiled (``arrays``), else lists."""
    return (int_array, float_array, flag_array) if arrays else (list, list, list)
