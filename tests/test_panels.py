"""No empty panels: for every shipped preset, a real run's recording and the panels of its
blueprint (``recording.blueprint``, read back as ``Run.show`` reads it), each with data to show."""

from collections import defaultdict
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import rerun as rr

from nnql_swarm.agent import agent_checkpoint
from nnql_swarm.learning.saved import read_fields
from nnql_swarm.protocol.config import PRESETS, SwarmConfig
from nnql_swarm.recording.blueprint import recorded_blueprint
from nnql_swarm.recording.shown import ca_learns
from tests.swarm_helpers import run_swarms

COUNTS_OF_NONE = ("metrics/collisions/per_episode", "metrics/refused")
"""Curves where a run of zeros is the news (no collision, no refusal), not a panel with
nothing in it."""
EPISODES = 11
"""Heat maps at episodes 0 and 10 (every tenth and the last)."""


def views(container):
    for item in getattr(container, "contents", None) or []:
        if hasattr(item, "class_identifier"):
            yield item
        yield from views(item)


def included(entity: str, origin: str, rules: list[str]) -> bool:
    """Whether a view's contents (Rerun's query expressions: ``+ path``, ``- path/**``,
    ``$origin``) take the entity in; the last rule that matches it decides."""
    taken = False
    for rule in rules:
        sign, _, path = rule.partition(" ") if rule[:2] in ("+ ", "- ") else ("+", "", rule)
        path = path.replace("$origin", origin).strip("/")
        subtree = path.endswith("/**")
        path = path.removesuffix("/**")
        if entity == path or (subtree and entity.startswith(path + "/")):
            taken = sign == "+"
    return taken


class Panels:
    """A run's recording: its chunks by entity, and the views of the blueprint it opens on."""

    def __init__(self, run: Path, claimed: dict | None = None) -> None:
        """``claimed``: config fields the blueprint is built with instead of the run's."""
        chunks = list(rr.chunk.RrdReader(run / "run.rrd").stream())
        self.config = SwarmConfig.from_json((run / "config.json").read_text())
        if claimed:
            self.config = replace(self.config, **claimed)
        self.temporal: dict[str, list] = defaultdict(list)
        self.static: dict[str, object] = {}
        for chunk in chunks:
            entity = chunk.entity_path.lstrip("/")
            if chunk.is_static:
                self.static[entity] = chunk.to_record_batch()
            else:
                self.temporal[entity].append(chunk.to_record_batch())
        self.views = list(views(recorded_blueprint(self.config, chunks).root_container))

    def shown(self, view) -> list[str]:
        """The entities with data over time a view shows: under its origin, those its contents
        name where it names them."""
        origin = str(view.origin).lstrip("/")
        rules = [str(rule) for rule in (view.contents if isinstance(view.contents, list)
                                        else [view.contents])]
        return [e for e in self.temporal if included(e, origin, rules)]

    def last(self, entity: str, column: str):
        """The column's value in the entity's newest row (by tick)."""
        rows = [(t, v) for batch in self.temporal[entity]
                for t, v in zip(batch.column("tick").to_pylist(),
                                batch.column(column).to_pylist()
                                if column in batch.schema.names else [None] * batch.num_rows)]
        return max(rows, key=lambda row: row[0])[1]

    def has_data(self, view) -> str | None:
        """None where the view has something to show; else what it lacks."""
        kind, origin = view.class_identifier, str(view.origin).lstrip("/")
        shown = self.shown(view)
        if kind == "TextDocument" and origin == "legend":
            return None if "legend" in self.static else "no key"
        if not shown:
            return "no data"
        if kind == "TimeSeries" and isinstance(view.contents, list):
            missing = {str(p).lstrip("/") for p in view.contents if "$" not in str(p)} - set(shown)
            if missing and not missing <= {"metrics/steps/paper_ql"} - set(self.temporal):
                return f"no {sorted(missing)}"
        if kind == "TimeSeries" and origin not in COUNTS_OF_NONE:
            values = [v[0] for e in shown for batch in self.temporal[e]
                      for v in batch.column("Scalars:scalars").to_pylist()]
            if not any(values):
                return "only zeros"
        if kind == "2D" and origin.startswith("agents/"):
            if self.last(f"{origin}/note", "Points2D:labels"):
                return "nothing learned (only the note)"
        if kind == "TextDocument" and origin.endswith("q_ds/table"):
            text = self.last(origin, "TextDocument:text")[0]
            if text.count("not met yet") == text.count("\n| ") - 1:
                return "no state met"
        if origin == "metrics/explored":
            if not all(self.last(e, "Scalars:scalars")[0] > 0 for e in shown):
                return "no state met"
        return None


@pytest.fixture(scope="module")
def preset_runs(tmp_path_factory):
    """A recorded in-process run of every preset, two at a time (each is one process)."""
    base = tmp_path_factory.mktemp("presets")
    options = ("--agents", "8", "--episodes", str(EPISODES), "--max-steps", "40", "--seed", "3",
               "--in-process")
    results = run_swarms({preset: (base / preset, (*options, "--preset", preset))
                          for preset in PRESETS})
    for preset, result in results.items():
        assert result.returncode == 0, (preset, result.stderr)
    return {preset: base / preset for preset in PRESETS}


@pytest.mark.full
@pytest.mark.parametrize("preset", list(PRESETS))
def test_every_panel_of_every_preset_has_data(preset_runs, preset):
    panels = Panels(preset_runs[preset])
    names = [view.name for view in panels.views]
    assert len(names) == len(set(names)) >= 8, names
    empty = {view.name: lack for view in panels.views if (lack := panels.has_data(view))}
    assert not empty, empty
    titles = " ".join(names)
    assert ("Q_CA" in titles) == ca_learns(panels.config), titles
    assert ("awaited" in titles) == (panels.config.algo in ("nnql", "nnql-dir")), titles


@pytest.mark.full
def test_a_q_ca_left_out_had_nothing_to_learn(preset_runs):
    """Where the blueprint leaves Q_CA out (the shield kept negotiating agents apart and the
    table starts at the value of never colliding), the checkpointed table never moved."""
    left_out = [p for p in PRESETS if not ca_learns(SwarmConfig(**PRESETS[p]))
                and PRESETS[p]["algo"] != "oracle"]
    assert "path-nnql" in left_out
    for preset in left_out:
        config = SwarmConfig(**PRESETS[preset])
        q_ca = read_fields(agent_checkpoint.checkpoint_path(preset_runs[preset] / "checkpoints", 0),
                           ())["q_ca"]
        assert np.all(np.asarray(q_ca) == config.optimistic), preset


@pytest.mark.full
def test_the_check_finds_an_empty_panel(preset_runs):
    """The checks above can fail: the default run's blueprint built as if its Q_CA learned (no
    optimistic start) shows a Q_CA panel, which has nothing; as if it negotiated in a
    distributed run, a QL run shows waits and negotiation waits it does not have."""
    panels = Panels(preset_runs["path-nnql"], {"optimistic": 0.0})
    lacks = {view.name: panels.has_data(view) for view in panels.views}
    assert lacks["Shared Q_CA: neighbour offset"] == "no data", lacks
    panels = Panels(preset_runs["ql"], {"algo": "nnql"})
    lacks = {view.name: panels.has_data(view) for view in panels.views}
    assert lacks["Intents awaited per tick"] == "only zeros", lacks
