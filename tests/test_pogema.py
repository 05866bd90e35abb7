"""POGEMA's instances (``world.pogema_instances``, ``maps/pogema/``): the committed files parse, each
family has its 128 instances of its agents on free, distinct, reachable cells; POGEMA's grids and
``[row, col]`` cells convert as its environment reads them; the converter writes what it reads and
refuses a bad source with one line."""

from dataclasses import replace

import pytest

from nnql_swarm.launch import pogema_import
from nnql_swarm.world import terrain as maps, pogema_instances as pogema

AGENTS = {"random": 64, "mazes": 64, "warehouse": 192, "movingai": 256}
MAPS = {"random": 128, "mazes": 128, "warehouse": 1, "movingai": 128}
SIDES = {"random": (17, 21), "mazes": (17, 21), "warehouse": (33, 46), "movingai": (64, 64)}


@pytest.mark.parametrize("family", list(pogema.FAMILIES))
def test_every_committed_instance_parses_with_its_agents_on_free_distinct_reachable_cells(family):
    folder = pogema.INSTANCES / family
    assert len(list(folder.glob("*.map"))) == MAPS[family]
    scens = pogema.scen_files(family)
    assert len(scens) == pogema.FAMILIES[family].instances == 128
    assert max(pogema.FAMILIES[family].agents) <= AGENTS[family]
    for scen in scens:
        # read_scen refuses a task on a wall or off the map, two starts or two goals on one
        # cell, or a goal its start cannot reach; and a file with fewer lines than agents
        instance = pogema.read_instance(scen, AGENTS[family])
        rows = instance.rows
        assert SIDES[family][0] <= len(rows) <= SIDES[family][1]
        assert len({(sx, sy) for sx, sy, _, _ in instance.tasks}) == AGENTS[family]
        assert len({(gx, gy) for _, _, gx, gy in instance.tasks}) == AGENTS[family]
        assert all(rows[y][x] == "." for t in instance.tasks for x, y in (t[:2], t[2:]))
        assert len(scen.read_text().splitlines()) == AGENTS[family] + 1


@pytest.mark.parametrize("family", list(pogema.FAMILIES))
def test_every_lifelong_instance_parses_with_its_agents_starts_and_goals(family):
    files = sorted((pogema.INSTANCES / family / "lifelong").glob("*.goals"))
    assert len(files) == 128
    for path in files:
        text = path.read_text()
        map_name = text.splitlines()[1][4:]
        rows = maps.read_map(pogema.INSTANCES / family / map_name)
        _, starts, goals = pogema.parse_goals(text, rows, str(path))
        assert len(starts) == len(set(starts)) == AGENTS[family]
        assert all(len(sequence) >= 1 for sequence in goals)


def test_the_first_random_instance_is_pogema_s_read_as_row_and_column():
    # validation-random-seed-000's first agent: agents_xy [9, 4], targets_xy [19, 1] (row, col)
    instance = pogema.read_instance(pogema.INSTANCES / "random" /
                                    "validation-random-seed-000.scen", 1)
    assert instance.tasks == ((4, 9, 1, 19),)
    assert instance.rows[0] == ".@....@.@..@..@......"
    assert (len(instance.rows[0]), len(instance.rows)) == (21, 20)


def test_a_pogema_grid_reads_its_special_cells_as_free_and_refuses_an_unknown_character():
    assert pogema.grid_rows(".#@\n$!.\n") == (".@.", "...")
    with pytest.raises(ValueError, match="row 2 holds 'x'"):
        pogema.grid_rows("...\n.x.", "g")
    with pytest.raises(ValueError, match="one length"):
        pogema.grid_rows("...\n..")
    assert pogema.tasks([[1, 2]], [[3, 0]]) == ((2, 1, 0, 3),)
    assert pogema.instance_stem("m", 7, 1) == "m-seed-007"
    assert pogema.instance_stem("m", 7, 128) == "m"


def test_a_goals_file_is_refused_with_its_line_where_a_cell_is_a_wall():
    rows = ("...", ".@.")
    text = pogema.format_goals("m.map", [(0, 0), (2, 1)], [[(1, 0), (0, 1)], [(1, 1)]])
    with pytest.raises(maps.MapError, match="g:4: \\(1, 1\\) is off the map or a wall"):
        pogema.parse_goals(text, rows, "g")
    assert pogema.parse_goals(text, ("...", "..."), "g") == (
        "m.map", ((0, 0), (2, 1)), (((1, 0), (0, 1)), ((1, 1),)))


SOURCE_MAPS = '"grid-a": |-\n  ..#.\n  .#..\n  ....\n"grid-b": |-\n  ....\n  ##..\n  ....\n'
SOURCE_MAPF = """environment:
  max_episode_steps: 128
scenarios:
  Scenario-0:
    agents_xy: [[0, 0], [2, 3]]
    map_name: grid-a
    seed: 0
    targets_xy: [[2, 0], [0, 1]]
  Scenario-1:
    agents_xy: [[0, 3], [2, 0]]
    map_name: grid-b
    seed: 0
    targets_xy: [[2, 3], [0, 0]]
"""
SOURCE_LMAPF = SOURCE_MAPF.replace("[[2, 0], [0, 1]]", "[[[2, 0], [0, 1]], [[0, 1]]]").replace(
    "[[2, 3], [0, 0]]", "[[[2, 3]], [[0, 0], [2, 1]]]")


def write_source(folder, mapf=SOURCE_MAPF):
    (folder / "01-random").mkdir(parents=True)
    (folder / "01-random" / "maps.yaml").write_text(SOURCE_MAPS)
    (folder / "01-random" / "01-random-mapf.yaml").write_text(mapf)
    (folder / "01-random" / "01-random-lmapf.yaml").write_text(SOURCE_LMAPF)


def convert(source, out, monkeypatch, capsys):
    """The converter's exit code and stderr on a source of 2 instances."""
    monkeypatch.setitem(pogema.FAMILIES, "random",
                        replace(pogema.FAMILIES["random"], instances=2))
    try:
        code = pogema_import.main([str(source), "--out", str(out), "--families", "random"])
    except SystemExit as stop:
        code = stop.code
    return code, capsys.readouterr().err


def test_the_converter_writes_maps_scenarios_and_goals_read_back_as_pogema_gave_them(
        tmp_path, monkeypatch, capsys):
    write_source(tmp_path / "src")
    code, err = convert(tmp_path / "src", tmp_path / "out", monkeypatch, capsys)
    assert code == 0, err
    assert "random: 2 maps, 2 one-shot instances of 2 agents, 2 lifelong" in err
    out = tmp_path / "out" / "random"
    assert maps.read_map(out / "grid-a.map") == ("..@.", ".@..", "....")
    first = pogema.read_instance(out / "grid-a.scen", 2)
    assert first.tasks == ((0, 0, 0, 2), (3, 2, 1, 0))
    assert out.joinpath("grid-a.scen").read_text().splitlines()[1].split("\t") == [
        "0", "grid-a.map", "4", "3", "0", "0", "0", "2", "2.00000000"]
    assert pogema.scen_files("random", tmp_path / "out") == [out / "grid-a.scen",
                                                             out / "grid-b.scen"]
    rows = maps.read_map(out / "grid-b.map")
    assert pogema.parse_goals((out / "lifelong" / "grid-b.goals").read_text(), rows) == (
        "grid-b.map", ((3, 0), (0, 2)), (((3, 2),), ((0, 0), (1, 2))))


@pytest.mark.parametrize("mapf, message", [
    (None, "maps.yaml: cannot be read (FileNotFoundError)"),
    (SOURCE_MAPF.replace("[[0, 0], [2, 3]]", "[[0, 2], [2, 3]]"), "the start (2, 0) is a wall"),
    (SOURCE_MAPF.replace("[[0, 0], [2, 3]]", "[[0, 0], [0, 0]]"), "no two agents start"),
    (SOURCE_MAPF.replace("Scenario-1", "Scenario-0"), "1 one-shot and 2 lifelong instances"),
])
def test_the_converter_refuses_a_bad_source_with_one_line(tmp_path, monkeypatch, capsys, mapf,
                                                          message):
    if mapf is not None:
        write_source(tmp_path / "src", mapf)
    code, err = convert(tmp_path / "src", tmp_path / "out", monkeypatch, capsys)
    assert code == 2 and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1 and message in err
