"""The swarm's command line (``launch/swarm.py``): the parsed options make a
:class:`nnql_swarm.api.Swarm`, which plays the run; ``--resume`` continues one.

    python launch/swarm.py --agents 8

The options, their checks and the run's flow are the API's (``api.command``); this module turns
its usage errors into one line and exit code 2, and says how the run ended.
"""

import sys

from nnql_swarm.api.command import (  # noqa: F401 (the command's parts, by their usual names)
    UsageError, build_parser, check_distributable, given_values, prepare_out_dir, resolve,
    resume, resume_command, run_in_process, run_processes, transports, unmerged,
)
from nnql_swarm.api.options import Launch
from nnql_swarm.api.python_api import Swarm
from nnql_swarm.recording.merge import merge_parts
from nnql_swarm.transport.runfiles import EXIT_NO_SPACE, out_of_space
from nnql_swarm.sim import restarts
from nnql_swarm.sim.resume import ResumeError
from nnql_swarm.launch.cli import EXIT_INTERRUPTED


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.resume:
        return resume_run(parser, args)
    try:
        swarm = Swarm.from_args(args)
        swarm.prepare()
    except UsageError as error:
        parser.error(str(error))
    try:
        code = swarm.play()
    except KeyboardInterrupt:  # in-process; the processes' launcher says it itself
        print(f"\n{interrupted_in_process(swarm)}", file=sys.stderr)
        return EXIT_INTERRUPTED
    except OSError as error:  # in-process: the processes' launcher says it itself
        if not out_of_space(error):
            raise
        print(f"no space left for the run's files in {swarm.out} ({error.strerror}): the run "
              f"stopped", file=sys.stderr)
        return EXIT_NO_SPACE
    if code == 0 and args.role != "agents":
        print(restarts.finished(swarm.out), file=sys.stderr)
    return code


def interrupted_in_process(swarm: Swarm) -> str:
    """What an interrupted ``--in-process`` run says: the command that continues it (its
    checkpoints are saved as it stops, and a distributed ``--resume`` plays the same run)."""
    try:
        check_distributable(swarm.config)
    except UsageError:
        return "interrupted (a run the simulator only plays cannot be resumed)"
    return f"interrupted: continue it with {resume_command(swarm.launch, swarm.out)}"


def resume_run(parser, args) -> int:
    """``--resume``: continue the run in ``--out`` from its last complete episode."""
    launch = Launch.of(args)
    try:
        config, start, out, lock = resume(launch, given_values(args))
    except (UsageError, ResumeError) as error:
        parser.error(str(error))
    if start.episode >= config.episodes:
        print(f"{out}: the run is already complete ({config.episodes} episodes)",
              file=sys.stderr)
        if unmerged(out) and merge_parts(out) is None:  # left by a run that could not merge
            return 1
        if args.role != "world":
            return 0
        # Agents elsewhere may still wait for the world that completed the run: this one only
        # tells them to stop.
    code = run_processes(launch, config, out, start)  # the lock held until this process ends
    if code == 0 and args.role != "agents":
        print(restarts.finished(out), file=sys.stderr)
    return code
