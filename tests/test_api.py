"""The Python API (``nnql_swarm.api``): its options are the command's, with the command's error
lines; the example script and the example notebook run (the notebook in a Jupyter kernel of this
environment, through ``nbclient``) and give the episodes as a table, the Q-tables as arrays, the
same run in-process and distributed, and the inline Rerun viewer, which draws the run in headless
Chromium (marker ``browser``); a run stopped from Python resumes to the run left alone."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from nnql_swarm.api import DETERMINISTIC_COLUMNS, Run, RunError, Swarm, resume
from nnql_swarm.launch import swarm_cli
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.world.metrics import COLUMNS
from tests.swarm_helpers import ROOT, run_swarm

EXAMPLE = ROOT / "examples" / "quickstart.py"
NOTEBOOK = ROOT / "examples" / "quickstart.ipynb"
AGENTS, EPISODES, STEPS, SEED = 3, 4, 20, 3
SMALL = ("--agents", str(AGENTS), "--episodes", str(EPISODES), "--max-steps", str(STEPS),
         "--seed", str(SEED))
COLUMNS_OF_RUN = list(DETERMINISTIC_COLUMNS)


def same_run(a: Run, b: Run) -> None:
    """Equal deterministic columns and equal Q-tables of every agent, bit for bit."""
    assert np.array_equal(a.episodes[COLUMNS_OF_RUN], b.episodes[COLUMNS_OF_RUN])
    for agent in range(a.config.n_agents):
        for x, y in zip(a.q_tables(agent), b.q_tables(agent)):
            assert np.array_equal(x, y), agent


@pytest.mark.parametrize("options, argv, message", [
    (dict(agents=0), ("--agents", "0"), "agents must be"),
    (dict(agents=80), ("--agents", "80"), "distinct start and goal cells"),
    (dict(grid="11by11"), ("--grid", "11by11"), "WIDTHxHEIGHT"),
    (dict(algo="dqn"), ("--algo", "dqn"), "algo must be one of"),
    (dict(goal_reward=float("nan")), ("--goal-reward", "nan"), "the goal reward must be"),
    (dict(episodes=-1), ("--episodes", "-1"), "episodes must be"),
    (dict(run_id="bad id!"), ("--run-id", "bad id!"), "invalid run id"),
    (dict(obstacle_density=0.9), ("--obstacle-density", "0.9"), "obstacle density"),
])
def test_a_bad_option_raises_the_line_the_command_prints(options, argv, message, capsys,
                                                         tmp_path):
    with pytest.raises(ValueError) as raised:
        Swarm(**options)
    assert message in str(raised.value)
    with pytest.raises(SystemExit) as exited:
        swarm_cli.main([*argv, "--out", str(tmp_path / "bad")])
    assert exited.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.endswith(f"error: {raised.value} (see --help)")
    assert not (tmp_path / "bad").exists()


def test_options_by_flag_or_field_and_a_config_give_the_configs_run():
    swarm = Swarm(preset="nnql", agents=5, radius=3, shared=True, grid=(9, 13), deadline=1.5,
                  run_id="named")
    config = swarm.config
    assert (config.algo, config.n_agents, config.interaction_radius, config.shared,
            config.width, config.height, config.tick_deadline_s, config.run_id) == \
        ("nnql", 5, 3, True, 9, 13, 1.5, "named")
    assert Swarm(n_agents=5, interaction_radius=3, preset="nnql", shared=True, grid="9x13",
                 tick_deadline_s=1.5, run_id="named").config == config
    assert Swarm(config).config == config
    odd = SwarmConfig(run_id="odd", n_agents=4, alpha=0.3, gamma=0.1, shared=False, shield=False,
                      obstacle_density=0.1, width=12, height=10, lookahead=2,
                      interaction_radius=4, wait_rule="reach", optimistic=0.0, ds_state="goal")
    assert Swarm(odd).config == odd
    assert Swarm(agents=4, shared=None).config.shared  # None: the preset's
    for bad in (dict(foo=1), dict(shared=1), dict(out="x"), dict(in_process=True)):
        with pytest.raises(ValueError, match="no option|on or off"):
            Swarm(**bad)
    with pytest.raises(ValueError, match="run it with --in-process"):
        Swarm(algo="oracle").run("never", distributed=True)


def test_a_swarm_builds_no_argv(monkeypatch, tmp_path):
    """``Swarm(...)`` makes its config directly (``api.options.config_of``): no parser is built
    or run, from the options to a finished run, and the command's parsed options give the same
    config."""
    import argparse

    def refused(*args, **kwargs):
        raise AssertionError("argparse invoked")

    for method in ("__init__", "parse_args", "parse_known_args"):
        monkeypatch.setattr(argparse.ArgumentParser, method, refused)
    swarm = Swarm(preset="nnql", agents=3, episodes=2, max_steps=10, seed=1, grid="7x6",
                  radius=3, optimistic=2, run_id="direct")
    assert swarm.config.optimistic == 2.0 and isinstance(swarm.config.optimistic, float)
    assert (swarm.config.width, swarm.config.height, swarm.config.interaction_radius) == (7, 6, 3)
    assert Swarm(swarm.config).config == swarm.config
    for bad, message in ((dict(agents="3"), "must be an integer"),
                         (dict(alpha="0.5"), "must be a number"),
                         (dict(preset="best"), "preset must be one of"),
                         (dict(topology="ring"), "topology must be one of")):
        with pytest.raises(ValueError, match=message):
            Swarm(**bad)
    run = swarm.run(tmp_path / "run", record=False)
    assert len(run.episodes) == 2
    monkeypatch.undo()
    args = swarm_cli.build_parser().parse_args(
        ["--preset", "nnql", "--agents", "3", "--episodes", "2", "--max-steps", "10", "--seed",
         "1", "--grid", "7x6", "--radius", "3", "--optimistic", "2", "--run-id", "direct"])
    assert Swarm.from_args(args).config == swarm.config


@pytest.fixture(scope="module")
def example(tmp_path_factory):
    """The example script on a small swarm, in-process and distributed."""
    out = tmp_path_factory.mktemp("example")
    done = subprocess.run([sys.executable, str(EXAMPLE), *SMALL, "--distributed", "--out",
                           str(out)], cwd=out, capture_output=True, text=True, timeout=300,
                          start_new_session=True)
    return out, done


@pytest.mark.full
def test_the_example_runs_in_process_and_distributed(example):
    out, done = example
    assert done.returncode == 0, done.stderr
    assert f"agent 0: Q_DS (441, 5), Q_CA (882, 5), all finite: True" in done.stdout
    assert "shared table: equal to agent 0's: True" in done.stdout
    assert "same episodes as in-process: True, same Q-tables: True" in done.stdout
    assert done.stdout.count("  episode ") == EPISODES  # its progress callback, once an episode
    assert "Traceback" not in done.stderr


@pytest.mark.full
def test_a_run_gives_its_episodes_as_a_table_and_its_q_tables_as_arrays(example):
    out, _ = example
    run = Run.open(out / "in-process")
    episodes = run.episodes
    assert episodes.shape == (EPISODES,) and episodes.dtype.names == COLUMNS
    assert episodes["episode"].tolist() == list(range(EPISODES))
    assert ((1 <= episodes["steps"]) & (episodes["steps"] <= STEPS)).all()
    assert ((0 <= episodes["arrived"]) & (episodes["arrived"] <= AGENTS)).all()
    assert np.isfinite(episodes["reward_sum"]).all() and (episodes["reward_sum"] > 0).all()
    assert run.complete and run.config.n_agents == AGENTS
    q_ds, q_ca = run.q_tables(0)
    assert q_ds.shape == (441, 5) and q_ca.shape == (882, 5)  # known_state: two blocks
    assert np.isfinite(q_ds).all() and np.isfinite(q_ca).all()
    assert (q_ds != run.config.optimistic).any(), "learned nothing"
    for agent in range(AGENTS):  # the default preset shares one table
        assert all(np.array_equal(a, b) for a, b in zip(run.q_tables(agent), run.shared_table()))
    assert run.recording == out / "in-process" / "run.rrd"
    for bad in (AGENTS, -1, "0"):
        with pytest.raises(ValueError, match="out of range"):
            run.q_tables(bad)


@pytest.mark.full
def test_the_apis_in_process_and_distributed_runs_and_the_commands_are_one_run(example,
                                                                               tmp_path):
    out, _ = example
    in_process, distributed = Run.open(out / "in-process"), Run.open(out / "distributed")
    same_run(in_process, distributed)
    assert all(np.array_equal(a, b) for a, b in zip(in_process.shared_table(),
                                                    distributed.shared_table()))
    assert (distributed.episodes["missed_intents"] == 0).all()
    command = run_swarm(tmp_path / "command", *SMALL, "--in-process", "--no-record")
    assert command.returncode == 0, command.stderr
    same_run(in_process, Run.open(tmp_path / "command"))
    assert Run.open(tmp_path / "command").recording is None
    with pytest.raises(FileNotFoundError, match="no recording"):
        Run.open(tmp_path / "command").show()


@pytest.mark.full
def test_show_hands_the_whole_recording_to_the_notebook_viewer(example):
    """Outside a notebook the viewer widget has no page: what it would send to one waits in its
    queue (``rerun_notebook.Viewer``'s, a private detail of Rerun 0.41), each message a
    recording stream of its own."""
    import rerun.notebook
    from rerun.chunk import RrdReader

    out, _ = example
    run = Run.open(out / "in-process")
    viewer = run.show()
    assert isinstance(viewer, rerun.notebook.Viewer)
    queued = viewer._viewer._event_queue
    assert queued and all(event == {"type": "rrd"} for event, _ in queued)
    shown = set()
    for i, (_, (data,)) in enumerate(queued):
        part = out / f"shown-{i}.rrd"
        part.write_bytes(data)
        reader = RrdReader(str(part))
        for store in reader.recordings():
            assert store.recording_id == run.config.run_id
            shown.update(reader.store(store=store).schema().entity_paths())
    whole = set(RrdReader(str(run.recording)).store().schema().entity_paths())
    assert "/world/agents/0/disc" in whole and "/agents/0/q_ds/table" in whole
    assert whole <= shown
    with pytest.raises(FileNotFoundError, match="no run here"):
        Run.open(ROOT / "nonexistent")


def view_names(reader, store) -> list[str]:
    """The names of the views and containers of a blueprint in a recording file."""
    names = []
    for chunk in reader.store(store=store).stream():
        batch = chunk.to_record_batch()
        for column in batch.schema.names:
            if column.endswith(":display_name"):
                names += [name for row in batch.column(column).to_pylist() for name in row or []]
    return sorted(names)


@pytest.mark.parametrize("how", ["in-process", "distributed"])
def test_show_opens_on_the_layout_the_run_was_recorded_with(example, how):
    """The notebook's viewer gets the blueprint the run's world sent: a distributed run's
    negotiation wait, an in-process run's ticks per episode, the known map of its map agent."""
    from rerun.chunk import RrdReader

    out, _ = example
    run = Run.open(out / how)
    blueprints = []
    for i, (_, (data,)) in enumerate(run.show()._viewer._event_queue):
        part = out / f"shown-{how}-{i}.rrd"
        part.write_bytes(data)
        shown = RrdReader(str(part))
        blueprints += [(shown, store) for store in shown.blueprints()]
    recorded = RrdReader(str(run.recording))
    assert len({store.recording_id for _, store in blueprints}) == 1, "one blueprint"
    names = sorted(name for reader, store in blueprints for name in view_names(reader, store))
    assert names == view_names(recorded, recorded.blueprints()[0])
    assert ("Negotiation wait (ms)" in names) == (how == "distributed")
    assert ("Ticks per episode" in names) == (how == "in-process")
    assert "Agent 0's known map and planned path" in names


@pytest.mark.full
def test_the_notebook_runs_in_a_kernel_and_shows_the_viewer_inline(tmp_path, monkeypatch):
    import nbformat
    from nbclient import NotebookClient

    kernels = tmp_path / "jupyter" / "kernels" / "python3"
    kernels.mkdir(parents=True)
    (kernels / "kernel.json").write_text(json.dumps({  # this environment's interpreter
        "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
        "display_name": "nnql-swarm", "language": "python"}))
    monkeypatch.setenv("JUPYTER_PATH", str(tmp_path / "jupyter"))
    work = tmp_path / "work"
    work.mkdir()
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    assert all(not cell.get("outputs") for cell in notebook.cells), "committed with outputs"
    NotebookClient(notebook, kernel_name="python3", timeout=300, store_widget_state=True,
                   resources={"metadata": {"path": str(work)}}).execute()

    code = [cell for cell in notebook.cells if cell.cell_type == "code"]
    text = "\n".join(output.get("text", "") + output.get("data", {}).get("text/plain", "")
                     for cell in code for output in cell.outputs)
    assert "Q_DS (441, 5) Q_CA (882, 5) finite: True" in text
    assert "agent 0's tables are the shared table: True" in text
    assert "same episodes: True same Q-tables: True" in text
    assert "10 of 10 episodes" in text
    runs = sorted(p.name for p in (work / "runs").iterdir())
    assert len(runs) == 2 and runs[1] == runs[0] + "-distributed"
    run = Run.open(work / "runs" / runs[0])
    assert run.episodes.shape == (10,) and run.recording is not None
    same_run(run, Run.open(work / "runs" / runs[1]))

    views = [output.data["application/vnd.jupyter.widget-view+json"]["model_id"]
             for output in code[-1].outputs
             if "application/vnd.jupyter.widget-view+json" in output.get("data", {})]
    state = notebook.metadata.widgets["application/vnd.jupyter.widget-state+json"]["state"]

    def tree(model_id: str):
        model = state[model_id]
        yield model
        for child in model["state"].get("children", []):
            yield from tree(child.removeprefix("IPY_MODEL_"))

    viewers = [m for view in views for m in tree(view)
               if m["state"].get("_anywidget_id") == "rerun_notebook.Viewer"]
    assert len(viewers) == 1, "the last cell shows one inline Rerun viewer"
    assert viewers[0]["state"]["_esm"].endswith("widget.js")
    assert viewers[0]["state"]["_height"] == 720


@pytest.mark.full
def test_a_run_stopped_from_python_resumes_to_the_run_left_alone(tmp_path):
    """A progress function that raises stops a distributed run (at the supervisor's next poll,
    some episodes later: enough of them that the run cannot end first)."""
    episodes = 40
    swarm = Swarm(agents=AGENTS, episodes=episodes, max_steps=STEPS, seed=SEED, run_id="stopped")
    seen = []

    def stop_after_two(row: dict) -> None:
        seen.append(row)
        if row["episode"] == 1:
            raise RuntimeError("enough")

    with pytest.raises(RuntimeError, match="enough"):
        swarm.run(tmp_path / "stopped", distributed=True, record=False, progress=stop_after_two)
    stopped = Run.open(tmp_path / "stopped")
    assert 2 <= len(stopped.episodes) < episodes and not stopped.complete
    assert [row["episode"] for row in seen] == [0, 1]
    with pytest.raises(ValueError, match="already holds a run"):
        swarm.run(tmp_path / "stopped")
    rest = []
    run = resume(tmp_path / "stopped", progress=rest.append)
    assert run.complete
    assert [row["episode"] for row in rest] == list(range(rest[0]["episode"], episodes))
    assert rest[0]["episode"] <= len(stopped.episodes)
    same_run(run, swarm.run(tmp_path / "alone", record=False))
    assert resume(tmp_path / "stopped").complete  # a complete run comes back as it is
    with pytest.raises(ValueError, match="no run to resume"):
        resume(tmp_path / "nothing")
    assert issubclass(RunError, RuntimeError)

WIDGET_PAGE = """<!doctype html>
<html><head><meta charset="utf-8"><link rel="stylesheet" href="widget.css">
<style>body {{ margin: 0; background: #fff; }}</style></head>
<body><div id="cell"></div>
<script type="module">
import widget from "./widget.js";
const state = {{_width: {width}, _height: {height}, _url: null, _panel_states: {{}},
               _fallback_token: null, _theme: "light"}};
const handlers = {{}};
const model = {{
  get: (name) => state[name],
  on: (event, handler) => {{ handlers[event] = handler; }},
  off: () => {{}},
  send: async (message) => {{
    if (message !== "ready") return;
    for (let i = 0; i < {messages}; i++) {{
      const data = await (await fetch(`message-${{i}}.rrd`)).arrayBuffer();
      handlers["msg:custom"]({{type: "rrd"}}, [new DataView(data)]);
    }}
    document.title = "sent";
  }},
}};
widget.render({{model, el: document.getElementById("cell")}});
</script></body></html>
"""
"""Jupyter's part, played by a page: the widget's module (``rerun_notebook``'s own ``widget.js``
and viewer, served from this machine) rendered as anywidget renders it, with a model that holds
the widget's state and hands it the messages ``Run.show`` queued, once the viewer says it is
ready, as the kernel would."""


@pytest.mark.full
@pytest.mark.browser
@pytest.mark.timeout(420)
def test_the_inline_viewer_shows_the_run_in_a_browser(tmp_path):
    """What ``Run.show`` gives a notebook's page draws the run: the grid and every agent's
    colour, in headless Chromium (as ``tests/test_browser.py`` checks the web viewer)."""
    import functools
    import http.server
    import threading

    import rerun_notebook

    from tests.browser import check_run, chromium, screenshot, wait_for
    from nnql_swarm.recording.palette import agent_colors

    run = Swarm(agents=4, episodes=1, max_steps=20, seed=3, run_id="inline").run(
        tmp_path / "run")
    queued = run.show()._viewer._event_queue  # what the kernel sends once the page is ready
    site = tmp_path / "site"
    site.mkdir()
    for name in ("widget.js", "widget.css", "re_viewer_bg.wasm"):
        (site / name).symlink_to(rerun_notebook.STATIC_DIR / name)
    for i, (_, (data,)) in enumerate(queued):
        (site / f"message-{i}.rrd").write_bytes(data)
    (site / "index.html").write_text(WIDGET_PAGE.format(width=1260, height=700,
                                                        messages=len(queued)))
    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, *_) -> None:
            pass

    handler = functools.partial(Quiet, directory=str(site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    colours = agent_colors(run.config.n_agents)
    try:
        with chromium() as browser:
            page = browser.new_page()
            errors = []
            page.on("pageerror", lambda error: errors.append(str(error)))
            page.goto(f"http://127.0.0.1:{server.server_address[1]}/index.html")
            def every_message_handed_over_and_drawn(image):
                # The run may be drawn before the page has fetched the last messages.
                assert page.title() == "sent", "the page has not handed over every message yet"
                return check_run(image, run.config.width, run.config.height, colours)

            try:
                image, found, _ = wait_for(page, every_message_handed_over_and_drawn, 240.0,
                                           every=2.0)
            except AssertionError as failure:
                screenshot(page, tmp_path / "inline.png")
                raise AssertionError(f"{failure}; page errors: {errors}; the page: "
                                     f"{tmp_path / 'inline.png'}") from None
            screenshot(page, tmp_path / "inline.png")
            assert not errors, errors
    finally:
        server.shutdown()
    assert len(found["pixels"]) == run.config.n_agents
