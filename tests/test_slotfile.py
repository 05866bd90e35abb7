"""transport.slotfile: the record rewritten in place, whole whatever is cut short; and the world's
checkpoint, which keeps the table of the episode before for a world killed before its row."""

import os

import numpy as np
import pytest

from nnql_swarm.learning.saved import CheckpointError
from nnql_swarm.transport import slotfile
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.world import world_checkpoint
from nnql_swarm.world.shared_table import SharedState, SharedTable


def record(episode: int) -> dict:
    rng = np.random.default_rng(episode)
    return {"q_ds": rng.random((441, 5)), "q_ca": rng.random((882, 5)), "episode": episode,
            "algo": "nnql", "count": np.int64(7)}


def slot_start(path, k: int) -> int:
    size = int.from_bytes(path.read_bytes()[8:12], "little")
    return 12 + k * size


def test_a_record_reads_back_as_written(tmp_path):
    path = tmp_path / "a" / "x.ckpt"
    slotfile.write(path, record(1))
    got = slotfile.read(path)
    assert got["episode"] == 1 and got["algo"] == "nnql" and got["count"] == 7
    assert np.array_equal(got["q_ds"], record(1)["q_ds"]) and got["q_ca"].shape == (882, 5)
    got["q_ds"][0, 0] = -1.0  # a copy, writable
    for episode in range(2, 7):
        slotfile.write(path, record(episode))
        assert slotfile.read(path)["episode"] == episode


def test_a_torn_newest_slot_leaves_the_one_before(tmp_path):
    path = tmp_path / "x.ckpt"
    for episode in (1, 2):  # episode 1 in slot 0, episode 2 in slot 1
        slotfile.write(path, record(episode))
    data = bytearray(path.read_bytes())
    data[slot_start(path, 1) + 500] ^= 0xFF  # half of episode 2's payload never reached the disk
    path.write_bytes(bytes(data))
    assert slotfile.read(path)["episode"] == 1
    slotfile.write(path, record(3))  # must go over the torn slot, never over episode 1
    assert slotfile.read(path)["episode"] == 3
    data = bytearray(path.read_bytes())
    data[slot_start(path, 1) + 500] ^= 0xFF
    path.write_bytes(bytes(data))
    assert slotfile.read(path)["episode"] == 1


def test_a_record_that_outgrows_its_slots_gets_a_new_file(tmp_path):
    path = tmp_path / "x.ckpt"
    slotfile.write(path, {"episode": 1, "note": "a"})
    slotfile.write(path, {"episode": 2, "note": "b" * 20_000})
    assert slotfile.read(path) == {"episode": 2, "note": "b" * 20_000}
    assert not (tmp_path / "x.ckpt.tmp").exists()


@pytest.mark.parametrize("content", [b"", b"not a checkpoint", b"NNQLSLT1" + bytes(40)])
def test_a_file_without_a_whole_record_is_refused(tmp_path, content):
    path = tmp_path / "x.ckpt"
    path.write_bytes(content)
    with pytest.raises(slotfile.SlotFileError):
        slotfile.read(path)
    slotfile.write(path, record(4))  # and the next write replaces it whole
    assert slotfile.read(path)["episode"] == 4


def test_both_slots_damaged_is_refused(tmp_path):
    path = tmp_path / "x.ckpt"
    for episode in (1, 2):
        slotfile.write(path, record(episode))
    data = bytearray(path.read_bytes())
    for k in (0, 1):
        data[slot_start(path, k) + 100] ^= 0xFF
    path.write_bytes(bytes(data))
    with pytest.raises(slotfile.SlotFileError, match="no whole record"):
        slotfile.read(path)


def test_what_msgpack_cannot_carry_is_refused_before_anything_is_written(tmp_path):
    path = tmp_path / "x.ckpt"
    slotfile.write(path, record(1))
    with pytest.raises(TypeError):
        slotfile.write(path, {"q_ds": np.array([object()], dtype=object)})
    assert slotfile.read(path)["episode"] == 1


def test_a_slot_file_reads_its_slots_once_and_then_remembers_them(tmp_path, monkeypatch):
    path = tmp_path / "x.ckpt"
    slotfile.write(path, record(1))  # a file another process wrote: episode 1 in slot 0
    reads = []
    real = slotfile._records
    monkeypatch.setattr(slotfile, "_records", lambda data: reads.append(1) or real(data))
    slots = slotfile.SlotFile(path)
    for episode in (2, 3, 4):
        slots.write(record(episode))
        assert [r["episode"] for r in slotfile.read_all(path)] == [episode, episode - 1]
    assert len(reads) == 1 + 3, "the slots read at the first write only (and by each read)"


def test_a_slot_file_whose_write_failed_reads_its_slots_again(tmp_path, monkeypatch):
    path = tmp_path / "x.ckpt"
    slots = slotfile.SlotFile(path)
    for episode in (1, 2):
        slots.write(record(episode))

    pwrite = os.pwrite

    def full(fd, data, offset):
        pwrite(fd, data[:500], offset)  # torn: the disk filled up half way
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(slotfile.os, "pwrite", full)
    with pytest.raises(OSError):
        slots.write(record(3))  # over episode 1's slot, which it tore
    monkeypatch.undo()
    assert slotfile.read(path)["episode"] == 2
    slots.write(record(4))  # must go over the torn slot, never over episode 2
    assert [r["episode"] for r in slotfile.read_all(path)] == [4, 2]


def test_the_record_before_the_newest_is_kept_until_the_next_write(tmp_path):
    path = tmp_path / "x.ckpt"
    slotfile.write(path, record(1))
    assert [r["episode"] for r in slotfile.read_all(path)] == [1]
    for episode in (2, 3):
        slotfile.write(path, record(episode))
    assert [r["episode"] for r in slotfile.read_all(path)] == [3, 2]


def test_a_world_killed_before_its_row_resumes_from_the_table_that_row_recorded(tmp_path):
    """The world writes its table, then the episode's row: killed in between, episodes.csv ends
    one episode before the file's newest table, and the resumed world takes the one before."""
    config = SwarmConfig(n_agents=4, run_id="slots")
    path = world_checkpoint.table_path(tmp_path)
    tables = {e: SharedTable(config).tables() for e in (3, 4)}
    for e, (q_ds, q_ca) in tables.items():
        q_ds[0, 0] = q_ca[0, 0] = float(e)
        world_checkpoint.save(path, SharedState(q_ds, q_ca), e, config)
    assert world_checkpoint.load(path, config, 3)[0][0, 0] == 3.0
    assert world_checkpoint.load(path, config, 4)[0][0, 0] == 4.0
    with pytest.raises(CheckpointError, match="holds the table after episode 4, not after "
                                              "episode 2"):
        world_checkpoint.load(path, config, 2)
