"""Copies of a saved run that open on another view: one agent followed tick by tick
(:func:`follow_copy`), or the learning curves alone (:func:`curves_copy`).

In the viewer a person follows an agent by hand: each agent is an entity of its own
(``recording.agent_entities``), so clicking its disc selects it (the selection panel shows its
parts), and the blueprint panel hides the others' (the eye beside ``world/agents/<id>``). This
module makes those views without a hand, for the docs' pictures (``docs/screenshot.py``): the
viewer follows the newest data, so a copy may end at a chosen tick.
"""

from pathlib import Path
from typing import Callable

import pyarrow.compute as pc
import rerun as rr

from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.recording.sinks import APP_ID


def follow_copy(run_dir: Path, out: Path, agent: int, until: int, since: int = 0) -> Path:
    """``run_dir``'s recording up to tick ``until``, opening on ``agent`` followed on the
    ``tick`` timeline (``recording.blueprint.blueprint(..., follow=agent)``); the world's and the
    known map's ticks only from ``since`` on (a smaller copy loads sooner)."""
    from nnql_swarm.recording.blueprint import blueprint

    return copy_opening_on(run_dir, out, lambda config, distributed, map_agent, reference:
                           blueprint(config, distributed, map_agent, reference, follow=agent),
                           until, since)


def curves_copy(run_dir: Path, out: Path) -> Path:
    """``run_dir``'s recording opening on its learning curves and the key, the whole page."""
    import rerun.blueprint as rrb

    from nnql_swarm.recording.blueprint import learning_curves
    from nnql_swarm.recording.world import LEGEND

    def curves(config, distributed, map_agent, reference):
        return rrb.Blueprint(
            rrb.Horizontal(learning_curves(config, distributed, reference),
                           rrb.TextDocumentView(origin=LEGEND, name="Key"), column_shares=[3, 1]),
            rrb.BlueprintPanel(state="collapsed"), rrb.SelectionPanel(state="collapsed"),
            rrb.TimePanel(timeline="episode", play_state="following", state="collapsed"),
            collapse_panels=False)

    return copy_opening_on(run_dir, out, curves, keep=("metrics/", LEGEND))


def copy_opening_on(run_dir: Path, out: Path, make: Callable, until: int | None = None,
                    since: int = 0, keep: tuple[str, ...] | None = None) -> Path:
    """Write ``out``: the recording of ``run_dir`` (its ``run.rrd``; up to tick ``until``, and
    the world's and known map's ticks from ``since`` on; static data whole; with ``keep``, only
    the entities whose paths start so) with the blueprint ``make(config, distributed, map_agent, reference)`` (the run's
    options read back as ``recording.blueprint.recorded_options`` reads them). Returns ``out``."""
    from nnql_swarm.recording.blueprint import recorded_options
    from nnql_swarm.recording.sinks import close_stream

    config = SwarmConfig.from_json((Path(run_dir) / "config.json").read_text())
    reader = rr.chunk.RrdReader(Path(run_dir) / "run.rrd")
    [store] = reader.recordings()
    chunks = list(reader.stream(store=store))
    distributed, reference, map_agent = recorded_options(chunks)
    stream = rr.RecordingStream(APP_ID, recording_id=store.recording_id)
    stream.set_sinks(rr.FileSink(str(out)), default_blueprint=make(config, distributed,
                                                                   map_agent, reference))
    for chunk in chunks:
        if keep is not None and not chunk.entity_path.lstrip("/").startswith(keep):
            continue
        batch = None if chunk.is_static or until is None else chunk.to_record_batch()
        if batch is None or "tick" not in batch.schema.names:
            stream.send_chunks(chunk)
            continue
        ticks = batch.column("tick")
        rows = pc.less_equal(ticks, until)
        if chunk.entity_path.lstrip("/").startswith(("world/", "known_map/")):
            rows = pc.and_(rows, pc.greater_equal(ticks, since))
        kept = batch.filter(rows)
        if kept.num_rows:
            names = [n for n in kept.schema.names if n != "rerun.controls.RowId"]
            kept = kept.select(names).replace_schema_metadata(
                {"rerun:entity_path": chunk.entity_path})
            stream.send_record_batch(kept, index=[n for n in names if n in chunk.timeline_names])
    close_stream(stream)
    return Path(out)
