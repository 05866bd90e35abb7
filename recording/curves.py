"""The experiments' learning curves, each in a recording of its own: the paper experiment's
(:func:`log_experiment`) and the swarm experiment's (:func:`log_swarm_curves`)."""

from pathlib import Path

import numpy as np

from nnql_swarm.recording.sinks import APP_ID


def log_experiment(specs, metrics, target, *, recording_id: str = "experiment"):
    """Log the paper experiment's learning curves, averaged over seeds, on the ``episode`` timeline.

    ``specs`` are ``experiment.paper.RunSpec`` (``algo``, ``random_step``, ``seed``); ``metrics`` is the
    matching ``experiment.paper.EpisodeMetrics`` (arrays ``(runs, episodes)``: ``steps``,
    ``collisions``, ``reward_ds``, ``reward_ca``, ``shortest``, ``arrived``). ``target`` is a path
    (a new ``.rrd`` file with its own blueprint is written there), or an open
    ``rr.RecordingStream``. Entities: ``experiment/<metric>/<algo>/k<k>`` for metric in
    ``collisions``, ``cumulative_collisions``, ``steps``, ``extra_steps`` (steps - shortest),
    ``reward_sum``, ``arrived``; one ``send_columns`` call each.
    """
    import rerun as rr

    from nnql_swarm.recording.sinks import close_stream

    groups: dict[tuple[str, int], list[int]] = {}
    for row, spec in enumerate(specs):
        groups.setdefault((spec.algo, int(spec.random_step)), []).append(row)
    if isinstance(target, rr.RecordingStream):
        stream, own = target, False
    else:
        stream, own = rr.RecordingStream(APP_ID, recording_id=recording_id), True
        stream.set_sinks(rr.FileSink(str(target)), default_blueprint=experiment_blueprint())
    curves = {
        "collisions": np.asarray(metrics.collisions, dtype=float),
        "cumulative_collisions": np.cumsum(np.asarray(metrics.collisions, dtype=float), axis=1),
        "steps": np.asarray(metrics.steps, dtype=float),
        "extra_steps": np.asarray(metrics.steps, dtype=float) - np.asarray(metrics.shortest),
        "reward_sum": np.asarray(metrics.reward_ds) + np.asarray(metrics.reward_ca),
        "arrived": np.asarray(metrics.arrived, dtype=float),
    }
    episodes = np.arange(curves["steps"].shape[1])
    for (algo, k), rows in sorted(groups.items()):
        for name, values in curves.items():
            path = f"experiment/{name}/{algo}/k{k}"
            stream.log(path, rr.SeriesLines(names=f"{algo} k={k} ({len(rows)} seeds)",
                                            colors=[_series_color(algo, k)]), static=True)
            stream.send_columns(path, [rr.TimeColumn("episode", sequence=episodes)],
                                rr.Scalars.columns(scalars=values[rows].mean(axis=0)))
    if own:
        close_stream(stream)
        return None
    return stream


def log_swarm_curves(curves: dict[str, dict[str, np.ndarray]], path: Path,
                     recording_id: str = "swarm-experiment") -> None:
    """The swarm experiment's learning curves (``experiment.swarm_experiment.curves``) into a new ``.rrd``:
    ``swarm/<metric>/<variant>`` on the ``episode`` timeline, one plot per metric."""
    import rerun as rr
    import rerun.blueprint as rrb

    from nnql_swarm.recording.sinks import close_stream

    stream = rr.RecordingStream(APP_ID, recording_id=recording_id)
    blueprint = rrb.Blueprint(rrb.Grid(*(rrb.TimeSeriesView(origin=f"swarm/{metric}", name=metric)
                                         for metric in curves), grid_columns=len(curves)))
    stream.set_sinks(rr.FileSink(str(path)), default_blueprint=blueprint)
    for metric, by_variant in curves.items():
        for variant, values in by_variant.items():
            entity = f"swarm/{metric}/{variant}"
            stream.log(entity, rr.SeriesLines(names=variant), static=True)
            stream.send_columns(entity, [rr.TimeColumn("episode", sequence=np.arange(values.size))],
                                rr.Scalars.columns(scalars=values))
    close_stream(stream)


_ALGO_COLORS = {"ql": (230, 120, 40), "nnql": (40, 140, 230), "nnql-dir": (60, 180, 90)}


def _series_color(algo: str, k: int) -> tuple[int, int, int]:
    """QL in oranges, nnQL in blues; larger k (less exploration) darker."""
    base = np.array(_ALGO_COLORS.get(algo, (160, 160, 160)), dtype=float)
    shade = 1.25 - 0.6 * min(max(k, 1), 20) / 20
    r, g, b = (int(v) for v in np.clip(base * shade, 0, 255))
    return r, g, b


def experiment_blueprint():
    import rerun.blueprint as rrb

    plot = rrb.TimeSeriesView
    return rrb.Blueprint(
        rrb.Grid(
            plot(origin="experiment/collisions", name="Collisions per episode (mean over seeds)"),
            plot(origin="experiment/cumulative_collisions", name="Cumulative collisions"),
            plot(origin="experiment/steps", name="Steps per episode"),
            plot(origin="experiment/extra_steps", name="Steps above the shortest path"),
            plot(origin="experiment/reward_sum", name="Reward sum"),
            plot(origin="experiment/arrived", name="Share of episodes arriving"),
            grid_columns=3,
        ),
        rrb.TimePanel(timeline="episode", state="collapsed"),
        collapse_panels=False,
    )
