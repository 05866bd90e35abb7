"""The benchmarks under ``bench/`` keep up with the code they time: every module imports (a name
renamed or moved elsewhere breaks no benchmark unseen), and ``bench.collisions`` classifies every
collision of a frozen episode with the simulator's own neighbour rows."""

import pkgutil
import subprocess
import sys
import time
from collections import Counter

import zenoh

import bench
from bench.collisions import classify
from nnql_swarm.experiment.maps_benchmark import MapsBenchmark, map_spec, run_config
from nnql_swarm.sim.runs import Batch, swarm_world
from tests.swarm_helpers import ROOT


def test_every_bench_module_imports():
    """In a process of its own: some set the kernel's mode in the environment as they load."""
    names = [module.name for module in pkgutil.iter_modules(bench.__path__)]
    assert {"collisions", "table1", "harness"} <= set(names)
    done = subprocess.run(
        [sys.executable, "-c", "import importlib, sys\n"
                               "for name in sys.argv[1:]: importlib.import_module('bench.' + name)",
         *names], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr


def test_every_bench_refuses_a_malformed_count_or_grid_in_one_line():
    """A benchmark given ``--agents 8,x`` or ``--grid 3`` stops at its argument parser (exit 2,
    a usage line), before it starts anything: no traceback."""
    names = [module.name for module in pkgutil.iter_modules(bench.__path__)]
    script = (
        "import contextlib, importlib, io, sys\n"
        "for name in sys.argv[1:]:\n"
        "    main = getattr(importlib.import_module('bench.' + name), 'main', None)\n"
        "    for flag in (['--agents', '8,x'], ['--grid', '3']):\n"
        "        if main is None: continue\n"
        "        sys.argv, err = [name, *flag], io.StringIO()\n"
        "        try:\n"
        "            with contextlib.redirect_stderr(err): main()\n"
        "        except SystemExit as stop: code = stop.code\n"
        "        else: code = 0\n"
        "        print(name, flag[0], code, err.getvalue().strip().splitlines()[-1:])\n")
    done = subprocess.run([sys.executable, "-c", script, *names], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert len(lines) >= 2 * 20, done.stdout
    for line in lines:
        name, flag, code, last = line.split(" ", 3)
        assert code == "2" and "error" in last, line
    assert any(line.startswith("world_tick --agents 2 ") and "comma-separated" in line
               for line in lines), done.stdout


def test_collisions_classifies_every_collision_of_a_frozen_episode():
    maps = MapsBenchmark(seeds=1, learners=("ql",))
    map_seed = maps.test_map_seeds(0)[0]
    config = run_config(maps, "ql", map_spec("random", map_seed), map_seed, 32, 1, frozen=True)
    batch = Batch(swarm_world(config), [config], record=True)
    episodes = batch.play(1)
    tally: Counter = Counter()
    classify(batch, 0, 0, int(episodes.steps[0, -1]), tally)
    assert sum(tally.values()) == int(episodes.collisions[0, -1]) > 0
    assert set(tally) <= {kind + gave_up for kind in (
        "stayed, hit", "into a wall", "into a parked agent", "swap",
        "into one that stayed, intent known", "into one that stayed, unknown, seen still",
        "into one that stayed, unknown, seen moving",
        "into one that stayed, unknown, unseen last step", "into one that was blocked",
        "two into one free cell", "two into one free cell, other's intent known",
        "two into a cell being left") for gave_up in ("", " (shield gave up)")}


def test_the_swarms_message_pattern_is_recorded_from_its_handlers_and_replays_through_zenoh():
    """``bench.pattern``: 8 agents of the default preset negotiate (answers, chains longer than
    the bare loop's two hops); what each agent waited for is what its neighbours sent it when
    they decided, so the replay of bare processes on loopback plays every tick to the end, its
    handlers idle, spinning, or doing a compiled handler's work on the run's own data
    (``--kernels``: each agent's last kernel calls, the world's last record checks)."""
    from bench.harness import swarm_config
    from bench.kernel_work import AGENT_KERNELS, KernelWork
    from bench.pattern import record, replay
    from nnql_swarm.agent.agent_machine import AgentMachine
    from nnql_swarm.protocol.config import DEFAULT_PRESET

    config = swarm_config(DEFAULT_PRESET, run_id="pattern-test", n_agents=8, width=11,
                          height=11, episodes=3, max_steps=100, seed=0)
    real_callback, real_init = zenoh.handlers.Callback, AgentMachine.__init__
    work = KernelWork(config.run_id)
    pattern = record(config, work)
    assert zenoh.handlers.Callback is real_callback, "the harness's stand-in stays inside it"
    assert AgentMachine.__init__ is real_init, "the kernels' capture stays inside the record"
    assert set(work.calls) == set(range(8)) and work.checks
    assert all(set(work.calls[agent]) == set(AGENT_KERNELS) for agent in range(8))
    for agent in range(8):
        work.part(agent).agent_work(agent)()  # the decision's work, as the replay does it
        assert set(work.part(agent).calls) == {agent}
    work.part(None).world_work()()
    assert 0 < pattern.timed_from < len(pattern.ticks)
    assert pattern.answers_per_tick() > 0.5 and 2 < pattern.hops_per_tick() < 8
    for tick in pattern.ticks:
        observed = {agent for agent, _ in tick.observations}
        assert set(tick.decisions) <= observed
        for agent, decision in tick.decisions.items():
            assert [to for kind, to, _ in decision.sends if kind == "intent"] in ([], [None])
            assert all(agent in tick.decisions[neighbour].answered
                       for neighbour in decision.awaits)
    assert pattern.recorded(len(pattern.ticks)) == pattern.timed_from
    result = replay(pattern, "mesh", timed_ticks=300, timeout_s=20)
    assert result["rate"] > 0, "the replay stalled"
    working = replay(pattern, "mesh", timed_ticks=300, timeout_s=20, work_us=100)
    assert working["rate"] > 0, "the replay stalled with its handlers working"
    compiled = replay(pattern, "mesh", timed_ticks=300, timeout_s=20, kernels=work)
    assert compiled["rate"] > 0, "the replay stalled with its handlers running the kernels"


def test_a_replayed_handler_works_for_the_cpu_time_it_is_given():
    """``bench.pattern --work-us``: :func:`busy` holds the thread for the CPU time it is given,
    on the thread's own clock (time another process holds the core is not work), and no more
    than the clock's reading adds."""
    from bench.pattern import busy

    for seconds in (0.0, 0.002, 0.02):
        cpu = time.thread_time()
        busy(seconds)
        spent = time.thread_time() - cpu
        assert seconds <= spent < seconds + 0.005, (seconds, spent)


def test_the_handlers_harness_cools_the_caches_before_each_message_outside_its_timing(tmp_path):
    """``bench.node_cpu --cold-caches``: the evictor runs once before each delivery, writes over
    more than a core's L2 cache, and its time is not counted in any handler's."""
    from bench.harness import swarm_config
    from bench.node_cpu import CacheEvictor, l2_cache_bytes, run
    from nnql_swarm.protocol.config import DEFAULT_PRESET

    config = swarm_config(DEFAULT_PRESET, run_id="cold-test", n_agents=4, width=8, height=8,
                          episodes=1, max_steps=20, seed=0)
    evictor = CacheEvictor()
    assert evictor.buffer.nbytes == 4 * l2_cache_bytes() > 0
    calls = []
    ticks = {}
    clock_now = [0.0]

    def clock() -> float:  # advances only in the handlers: the evictor's time would show
        return clock_now[0]

    def before_each() -> None:
        evictor()
        calls.append((evictor.buffer[0], evictor.buffer[-1]))
        clock_now[0] += 1.0  # time that must not be counted

    ticks["cooled"], wire = run(config, tmp_path / "cooled", False, clock,
                                before_each=before_each)
    delivered = sum(wire.count.values())
    assert len(calls) == delivered > ticks["cooled"]
    assert calls == [(float(k), float(k)) for k in range(1, delivered + 1)]
    assert evictor.buffer.sum() == delivered * evictor.buffer.size, "every byte, every time"
    assert sum(wire.seconds.values()) == 0.0, "the evictor's time is outside the handlers'"
    ticks["warm"], _ = run(config, tmp_path / "warm", False)
    assert ticks["warm"] == ticks["cooled"], "cooling the caches changes no message"


def test_the_handler_floor_times_every_handler_on_real_observations():
    """``bench.handler_floor``: what it times are a run's real observations, which the codec
    accepts for every agent; each handler is called once a payload, cooled before each call
    when told."""
    from bench.handler_floor import HANDLERS, RUN_ID, observations, time_calls
    from nnql_swarm.protocol.messages import Observation, parse

    payloads = observations(4, 1)
    decoded = [parse(p, Observation, RUN_ID) for p in payloads]
    assert {obs.agent for obs in decoded} == set(range(4))
    assert [obs.tick for obs in decoded] == sorted(obs.tick for obs in decoded)
    for handler in HANDLERS.values():
        cooled = []
        assert time_calls(handler, payloads[:5], lambda: cooled.append(1)) >= 0.0
        assert len(cooled) == 5


def test_the_agents_parts_are_timed_where_the_machine_calls_them():
    """``bench.agent_parts``: every part is timed on the real handlers of a run (in a process of
    its own: it wraps the machine's collaborators), and each observation is decided once."""
    from bench.agent_parts import KERNEL_PARTS, PARTS

    done = subprocess.run([sys.executable, "-m", "bench.agent_parts", "--agents", "4",
                           "--episodes", "2", "--repeats", "1"], cwd=ROOT, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    lines = {line[:30].strip(): line[30:].split() for line in done.stdout.splitlines()[1:]}
    assert set(lines) == {name for name, _, _ in PARTS} | {name for name, _ in KERNEL_PARTS}, \
        done.stdout
    calls = {name: int(figures[1].strip("()")) for name, figures in lines.items()}
    assert all(float(figures[0]) > 0 for figures in lines.values()), done.stdout
    assert calls["the decision (act)"] == calls["the observation, in all"] > 0, done.stdout
    assert calls["the decision's kernel"] == calls["the decision (act)"], done.stdout
    assert calls["the plan's kernel"] == calls["the negotiation's plan"], done.stdout
    assert float(lines["the decision's kernel"][0]) < float(lines["the decision (act)"][0])


def test_the_cpu_split_counts_the_receiving_threads_samples_by_shared_object():
    """``bench.cpu_split`` reads ``perf script -F comm,time,ip,dso``: only Zenoh's receiving
    threads count (where every handler runs), and only while the timed ticks ran, each sample put
    to the part its shared object belongs to."""
    from bench.cpu_split import FREQUENCY, OTHER, per_tick_us, receiving_samples

    script = "\n".join([
        "            rx-0 1796641630.100000:  7f90a1b2c3d4 (/root/.pyenv/versions/3.11.7/lib/"
        "libpython3.11.so.1.0)",
        "            rx-0 1796641630.200000:  7f90a1b2c3d4 (/root/.pyenv/versions/3.11.7/lib/"
        "libpython3.11.so.1.0)",
        "            rx-1 1796641630.300000:  ffffffff82250979 ([kernel.kallsyms])",
        "            rx-0 1796641630.300001:  7f903c6c10c2 (/work/.venv/lib/python3.11/"
        "site-packages/zenoh/zenoh.abi3.so)",
        "            rx-2 1796641630.400000:  7f11 (/x/site-packages/numpy/core/"
        "_multiarray_umath.cpython-311-x86_64.so)",
        "            rx-0 1796641630.400000:  7f12 (/x/site-packages/msgspec/"
        "_core.cpython-311-x86_64-linux-gnu.so)",
        "            rx-0 1796641630.400000:  7f13 (/root/.cache/nnql/"
        "nnql_ahead_kernels.cpython-311-x86_64.so)",
        "            rx-0 1796641630.400000:  7f14 (/usr/lib/x86_64-linux-gnu/libc.so.6)",
        "            rx-0 1796641630.400000:  7f15 (/usr/lib/x86_64-linux-gnu/libz.so.1.2.13)",
        "            rx-0 1796641629.999999:  7f14 (/usr/lib/x86_64-linux-gnu/libc.so.6)",  # early
        "            rx-0 1796641631.000001:  7f14 (/usr/lib/x86_64-linux-gnu/libc.so.6)",  # late
        "         swapper     0 1796641630.400000:  ffffffff8224215b ([kernel.kallsyms])",  # idle
        "  nnql-agent 5 pa 1796641630.400000:  7f90a1b2c3d4 (/root/.pyenv/versions/3.11.7/lib/"
        "libpython3.11.so.1.0)",  # a main thread
        "          python 1796641630.400000:  7fd69f5c5c61 (/usr/lib/x86_64-linux-gnu/"
        "ld-linux-x86-64.so.2)",
        "not a sample line",
    ])
    counts = receiving_samples(script, (1796641630.0, 1796641631.0))
    assert counts == {"Python interpreter": 2, "Linux kernel": 1, "Zenoh": 1, "numpy": 1,
                      "msgspec (the codec)": 1, "our compiled kernels": 1, "C library": 1,
                      OTHER: 1}
    assert per_tick_us(counts, 10)["Python interpreter"] == 2e6 / FREQUENCY / 10


def test_alternately_reads_each_figure_as_the_least_of_its_decimal_numbers():
    from bench.alternately import figures

    assert figures("8 agents, 267 ticks a repeat; us (median over repeats)\n"
                   "  one observation            45.5  (45.4 45.6)\n"
                   "  prepare (updates, noise)    4.3 (1668)     3.9 (1668)\n"
                   "  nnql-agent 0                 153\n") == {
        "one observation": 45.4, "prepare (updates, noise)": 3.9}


def test_alternately_runs_a_benchmark_in_each_tree_by_turns_and_prints_each_figures_least():
    """``bench.alternately`` on this tree against itself: every figure of the benchmark's output,
    in both trees, with B over A; a directory that is not a checkout is refused in one line."""
    command = [sys.executable, "-m", "bench.alternately", "--a-dir", str(ROOT), "--rounds", "2",
               "--", "bench.node_cpu", "--agents", "2", "--episodes", "1", "--repeats", "1",
               "--cpu-time"]
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    rows = {line.split("  ")[1].strip(): line for line in done.stdout.splitlines()[2:]}
    assert {"one observation", "one intent", "whole tick"} <= set(rows), done.stdout
    a, b, ratio = rows["whole tick"].split()[2:5]
    assert float(a) > 0 and float(b) > 0 and abs(float(ratio) - float(b) / float(a)) < 0.01
    assert done.stderr.count("done") == 4, done.stderr  # two rounds, two trees
    refused = subprocess.run([*command[:4], "/proc", *command[5:]], cwd=ROOT,
                             capture_output=True, text=True, timeout=60)
    assert refused.returncode == 2 and "not a checkout" in refused.stderr.splitlines()[-1]
