"""The web viewer in a real browser: a recording served by ``rerun --serve-web``, opened in
headless Chromium (Debian's ``chromium``, driven by Playwright), and what its screenshots show.

Used by ``tests/test_browser.py`` and ``docs/screenshot.py``. The viewer draws with WebGL, which
headless Chromium gets from SwiftShader (software); on a busy 2-core machine a short run shows
30 to 45 s after the page opens, most of it the viewer's own loading.

The pixel checks (:func:`find_grid`, :func:`colour_pixels`, :func:`check_run`) raise
``AssertionError`` saying what they did not find, so that a poll can retry them and a test can
report the last failure.
"""

import io
import os
import tempfile
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator
from urllib.parse import quote

import numpy as np

from nnql_swarm.recording.viewers import grpc_url, saved_run_server
from nnql_swarm.transport.ports import free_port

CHROMIUM = Path(os.environ.get("NNQL_CHROMIUM", "/usr/bin/chromium"))
"""Debian's ``chromium`` (``apt-get install chromium``); ``NNQL_CHROMIUM`` names another."""

CHROMIUM_ARGS = ["--use-angle=swiftshader", "--enable-unsafe-swiftshader"]
"""WebGL from SwiftShader, even where there is a GPU (the viewer needs WebGL). Playwright adds
the rest: no sandbox (which root needs), no background networking, no component updates."""

GRID_GREY = (90, 90, 90)
"""The colour ``recording/world.py`` draws the grid's lines in."""

BACKGROUND = (255, 255, 255)
"""The 2D view's background in the viewer's light theme (the page asks for it)."""


def unavailable() -> str | None:
    """Why the browser tests cannot run here, or None when they can."""
    missing = []
    if not (CHROMIUM.is_file() and os.access(CHROMIUM, os.X_OK)):
        missing.append(f"{CHROMIUM} (Debian's chromium)")
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        missing.append("playwright (the 'browser' extra)")
    return f"{' and '.join(missing)} missing" if missing else None


@dataclass(frozen=True)
class Viewer:
    """A running ``rerun --serve-web``: where the browser goes."""

    web_port: int
    grpc_port: int

    def url(self, grpc_port: int | None = None) -> str:
        """The viewer's page, reading the recording from ``grpc_port`` (default: the server's)."""
        source = quote(grpc_url(self.grpc_port if grpc_port is None else grpc_port), safe="")
        return f"http://127.0.0.1:{self.web_port}/?url={source}&persist=0&theme=light"


@contextmanager
def web_viewer(recording: Path | None, log: Path | None = None) -> Iterator[Viewer]:
    """``rerun --serve-web`` on free ports, serving ``recording`` (or nothing), until the end,
    as ``launch/view.py`` serves one (``recording.viewers.saved_run_server``); its output kept
    in ``log`` where given."""
    viewer = Viewer(web_port=free_port(), grpc_port=free_port())
    files = [] if recording is None else [recording]
    with (open(log, "w+") if log else tempfile.TemporaryFile("w+")) as out, \
            saved_run_server(files, viewer.grpc_port, viewer.web_port, out):
        yield viewer


@contextmanager
def chromium(chromium_path: Path = CHROMIUM, args: list[str] = CHROMIUM_ARGS,
             size: tuple[int, int] = (1280, 720)) -> Iterator:
    """Headless Chromium with a fresh profile (a Playwright ``BrowserContext``)."""
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory(prefix="nnql-chromium-") as profile, \
            sync_playwright() as pw:
        context = pw.chromium.launch_persistent_context(
            profile, executable_path=str(chromium_path), headless=True,
            args=args, viewport={"width": size[0], "height": size[1]})
        try:
            yield context
        finally:
            context.close()


def screenshot(page, path: Path | None = None) -> np.ndarray:
    """The page as RGB bytes ``(height, width, 3)``; also saved to ``path`` if given."""
    from PIL import Image

    png = page.screenshot(timeout=120_000)  # a busy SwiftShader can take its time
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(png)
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))


def wait_for(page, check: Callable[[np.ndarray], object], timeout: float,
             every: float = 1.0) -> tuple[np.ndarray, object, float]:
    """Screenshot the page until ``check(image)`` stops raising ``AssertionError``.

    Returns the image, what ``check`` returned and the seconds it took; after ``timeout``
    seconds, raises the last failure.
    """
    start = time.monotonic()
    while True:
        image = screenshot(page)
        try:
            return image, check(image), time.monotonic() - start
        except AssertionError as failure:
            if time.monotonic() - start > timeout:
                raise AssertionError(f"after {time.monotonic() - start:.0f} s: {failure}") \
                    from None
        time.sleep(every)


@dataclass(frozen=True)
class Grid:
    """Where the grid's lines are in a screenshot (pixel centres, left to right, top to bottom)."""

    xs: tuple[int, ...]
    ys: tuple[int, ...]

    @property
    def box(self) -> tuple[int, int, int, int]:
        return self.xs[0], self.ys[0], self.xs[-1], self.ys[-1]

    @property
    def cell(self) -> float:
        return (self.xs[-1] - self.xs[0]) / (len(self.xs) - 1)


def near(image: np.ndarray, colour, tolerance: int) -> np.ndarray:
    """Which pixels are within ``tolerance`` of ``colour`` in every channel."""
    return np.abs(image.astype(np.int16) - np.asarray(colour, np.int16)).max(axis=2) <= tolerance


def ink(image: np.ndarray, colour=GRID_GREY, background=BACKGROUND,
        tolerance: int = 12) -> np.ndarray:
    """How much of ``colour`` each pixel holds, blended over ``background``: 1 on the colour,
    0 on the background or on anything not between the two (a line that falls between two rows
    of pixels is drawn as two rows of half the ink)."""
    pixels = image.astype(np.float32)
    bg, fg = np.asarray(background, np.float32), np.asarray(colour, np.float32)
    share = (pixels - bg) @ (fg - bg) / float((fg - bg) @ (fg - bg))
    off = np.abs(pixels - (bg + share[..., None] * (fg - bg))).max(axis=2)
    return np.where((off <= tolerance) & (share >= 0.15) & (share <= 1.1),
                    np.clip(share, 0.0, 1.0), 0.0)


def _evenly_spaced(profile: np.ndarray, count: int) -> list[float] | None:
    """Exactly ``count`` evenly spaced lines in a profile (the ink of each column or row),
    neither more nor fewer in a row. A line is a run of columns with at least a quarter of the
    most ink, whose ink adds up to at least half the most inked run's. None if there are none."""
    if profile.max(initial=0) < 20:
        return None
    hits = np.flatnonzero(profile >= profile.max() / 4)
    runs = np.split(hits, np.flatnonzero(np.diff(hits) > 1) + 1)
    totals = np.array([profile[run].sum() for run in runs])
    centres = [float(np.average(run, weights=profile[run]))
               for run, total in zip(runs, totals) if total >= totals.max() / 2]
    first = 0
    while first < len(centres) - 1:
        run = centres[first:first + 2]
        for centre in centres[first + 2:]:
            if abs(centre - run[-1] - (run[1] - run[0])) > 2:
                break
            run.append(centre)
        if len(run) == count and run[1] - run[0] >= 8:
            return run
        first += len(run) - 1
    return None


def find_grid(image: np.ndarray, columns: int, rows: int, colour=GRID_GREY) -> Grid:
    """The ``columns`` x ``rows`` grid of square cells drawn in ``colour``: ``columns + 1``
    evenly spaced vertical lines, and between them ``rows + 1`` horizontal ones at the same
    spacing, each line drawn over at least 80 % of the grid's extent."""
    lines = ink(image, colour)
    xs = _evenly_spaced(lines.sum(axis=0), columns + 1)
    if xs is None:
        raise AssertionError(f"no {columns}x{rows} grid: no {columns + 1} evenly spaced "
                             f"vertical lines of {colour} (ink on {np.count_nonzero(lines)} "
                             f"pixels)")
    x0, x1 = round(xs[0]), round(xs[-1])
    ys = _evenly_spaced(lines[:, x0:x1 + 1].sum(axis=1), rows + 1)
    if ys is None:
        raise AssertionError(f"no {columns}x{rows} grid: {columns + 1} vertical lines at x "
                             f"{x0}..{x1}, but no {rows + 1} evenly spaced horizontal ones")
    grid = Grid(tuple(round(x) for x in xs), tuple(round(y) for y in ys))
    y0, y1 = grid.ys[0], grid.ys[-1]
    if abs((y1 - y0) / rows - grid.cell) > 2:
        raise AssertionError(f"grid lines at x {grid.xs} and y {grid.ys} make no square cells")
    covered = ~near(image, BACKGROUND, 12)  # something drawn there, maybe over a line
    for x in grid.xs:
        band = np.s_[y0:y1 + 1, max(x - 1, 0):x + 2]
        check_line(lines[band].max(axis=1) > 0, covered[band].all(axis=1), f"vertical grid "
                   f"line at x={x}")
    for y in grid.ys:
        band = np.s_[max(y - 1, 0):y + 2, x0:x1 + 1]
        check_line(lines[band].max(axis=0) > 0, covered[band].all(axis=0), f"horizontal grid "
                   f"line at y={y}")
    return grid


def check_line(inked: np.ndarray, covered: np.ndarray, name: str) -> None:
    """A grid line drawn along its whole length where nothing hides it: its ink over at least
    half of it, and ink or something drawn over it (arrows, labels, agents) along 80 %."""
    drawn, seen = float(np.mean(inked | covered)), float(np.mean(inked))
    if drawn < 0.8 or seen < 0.5:
        raise AssertionError(f"{name} drawn over {seen:.0%} only ({drawn:.0%} with what "
                             f"covers it)")


def colour_pixels(image: np.ndarray, grid: Grid, colours: np.ndarray,
                  tolerance: int = 12) -> list[int]:
    """How many pixels inside the grid are each of ``colours`` (``(n, 3)`` RGB bytes)."""
    x0, y0, x1, y1 = grid.box
    inside = image[y0:y1 + 1, x0:x1 + 1]
    return [int(np.count_nonzero(near(inside, c, tolerance))) for c in colours]


def check_run(image: np.ndarray, columns: int, rows: int, colours: np.ndarray) -> dict:
    """The world view of a run: the grid, and inside it each agent's colour on at least a tenth
    of a cell's area (its goal box alone is about a third). Returns what it found."""
    grid = find_grid(image, columns, rows)
    counts = colour_pixels(image, grid, colours)
    least = 0.1 * grid.cell ** 2
    missing = [i for i, count in enumerate(counts) if count < least]
    if missing:
        raise AssertionError(
            f"grid at {grid.box}, but agents {missing} have too few pixels of their colours "
            f"{[tuple(int(v) for v in colours[i]) for i in missing]} inside it "
            f"(pixels per agent {counts}, at least {least:.0f} wanted)")
    return {"grid": grid.box, "cell": grid.cell, "pixels": counts}


def cell_centre(grid: Grid, x: float, y: float) -> tuple[float, float]:
    """The pixel of the world's point ``(x, y)``, the centre of cell ``(x, y)`` at integers (the
    view's ``y`` grows downwards, like the world's)."""
    return grid.xs[0] + (x + 0.5) * grid.cell, grid.ys[0] + (y + 0.5) * grid.cell


def window(image: np.ndarray, grid: Grid, x: float, y: float, half: float,
           below: float = 0.0) -> np.ndarray:
    """The pixels of the square of ``2 half`` cells around world point ``(x, y)``, moved down
    by ``below`` cells."""
    cx, cy = cell_centre(grid, x, y + below)
    r = half * grid.cell
    return image[max(round(cy - r), 0):round(cy + r) + 1, max(round(cx - r), 0):round(cx + r) + 1]


def check_walls(image: np.ndarray, grid: Grid, walls, free, colour, tolerance: int = 16) -> dict:
    """Every wall cell (``walls``, ``(k, 2)`` cells) is a block of ``colour``: at least 60 % of
    the middle half of the cell, and no free cell (``free``) is (at most 20 %): the walls are
    drawn where they are, each one."""
    def share(cell) -> float:
        return float(near(window(image, grid, *cell, 0.25), colour, tolerance).mean())

    drawn = [share(cell) for cell in walls]
    missing = [tuple(cell) for cell, s in zip(walls, drawn) if s < 0.6]
    if missing:
        raise AssertionError(f"{len(missing)} of {len(walls)} walls not drawn in "
                             f"{tuple(colour)}: {missing[:8]} (shares {drawn[:8]})")
    wrong = [tuple(cell) for cell in free if share(cell) > 0.2]
    if wrong:
        raise AssertionError(f"free cells drawn as walls: {wrong[:8]}")
    return {"walls": len(walls), "least": min(drawn)}


LABEL_BACKGROUND = (232, 232, 232)
"""The light pill the viewer draws under a label in its light theme (near this grey)."""


def check_labels(image: np.ndarray, grid: Grid, places, colours, least: float = 0.65) -> dict:
    """A label under each of ``places`` (``(k, 2)`` cells: agents and goals), in the colour of
    its thing (``colours`` ``(k, 3)``): the viewer draws a label as coloured text on a light,
    translucent pill just below the point or box. At least ``least`` of the places must show
    one, each with pill pixels and text of its colour (a wall or arrows under a pill hide a
    few)."""
    found = []
    for (x, y), colour in zip(places, colours):
        area = window(image, grid, x, y, 0.55, below=0.6)
        pill = near(area, LABEL_BACKGROUND, 14).mean()
        text = int(np.count_nonzero(near(area, colour, 60)))
        found.append(pill > 0.05 and text >= 3)
    share = float(np.mean(found)) if found else 0.0
    if share < least:
        missing = [tuple(map(int, p)) for p, ok in zip(places, found) if not ok]
        raise AssertionError(f"labels under only {share:.0%} of {len(found)} agents and goals "
                             f"(missing under {missing[:10]})")
    return {"labelled": share}


def check_arrows(image: np.ndarray, grid: Grid, origins, vectors, colours,
                 tolerance: int = 40, least: float = 0.6) -> dict:
    """Arrows drawn: around the middle of each arrow (``origins``, ``vectors`` in cells), pixels
    of its colour; at least ``least`` of them (others drawn over some)."""
    seen = []
    for (x, y), (dx, dy), colour in zip(origins, vectors, colours):
        area = window(image, grid, x + dx / 2, y + dy / 2, 0.12)
        seen.append(np.count_nonzero(near(area, colour, tolerance)) >= 2)
    share = float(np.mean(seen)) if seen else 0.0
    if not seen or share < least:
        raise AssertionError(f"only {share:.0%} of {len(seen)} arrows visible")
    return {"arrows": len(seen), "visible": share}


def check_colours(image: np.ndarray, grid: Grid, colours, tolerance: int = 5,
                  least: float = 0.9) -> dict:
    """Every agent in a colour of its own: inside the grid, pixels of each agent's colour (its
    disc, goal, trail and moves) on at least a tenth of a cell's area, within a tolerance under
    half the least difference between two agents' colours, so that no pixel counts for two
    agents. At least ``least`` of the agents (one that stayed put, under others' labels, shows
    little)."""
    colours = np.asarray(colours, dtype=np.int16)
    apart = np.abs(colours[:, None] - colours[None]).max(axis=2)
    np.fill_diagonal(apart, 255)
    if len(colours) > 1 and 2 * tolerance >= apart.min():
        raise AssertionError(f"agents' colours only {apart.min()} apart: a tolerance of "
                             f"{tolerance} cannot tell them apart")
    counts = np.array(colour_pixels(image, grid, colours.astype(np.uint8), tolerance))
    seen = counts >= 0.1 * grid.cell ** 2
    if seen.mean() < least:
        raise AssertionError(f"only {seen.mean():.0%} of {len(seen)} agents show their own "
                             f"colour (missing: {np.flatnonzero(~seen)[:10].tolist()})")
    return {"own colour": float(seen.mean())}


@dataclass(frozen=True)
class Episode:
    """What the world view draws of one episode, read back from a recording: where each agent
    ended it, the goals, every announced move and every wait (arrows, in cells)."""

    agents: np.ndarray  # (n, 2) cells at the episode's last tick
    goals: np.ndarray  # (n, 2)
    moves: tuple[np.ndarray, np.ndarray, np.ndarray]  # origins, vectors, agent of each move
    waits: tuple[np.ndarray, np.ndarray]  # origins, vectors
    ages: np.ndarray  # of each move: the steps announced after it in the episode


def last_episode(recording: Path, n_agents: int) -> Episode:
    """The newest episode of a run's ``run.rrd`` (the one the viewer opens on), of
    ``n_agents`` agents, each (or each group) an entity of its own
    (``recording.agent_entities``)."""
    import rerun as rr

    from nnql_swarm.recording.agent_entities import DISC, GOAL, INTENT, WAITS, agents_of

    rows: dict[tuple[str, int], list] = {}  # (part, first agent of its entity): its rows
    holds: dict[int, np.ndarray] = {}
    for chunk in rr.chunk.RrdReader(recording).stream():
        agents = agents_of(chunk.entity_path, n_agents)
        part = chunk.entity_path.rsplit("/", 1)[-1]
        if agents is None or chunk.is_static or part not in (DISC, GOAL, INTENT, WAITS):
            continue
        holds[int(agents[0])] = agents
        batch = chunk.to_record_batch()
        columns = {name: batch.column(name).to_pylist() for name in batch.schema.names}
        rows.setdefault((part, int(agents[0])), []).extend(
            {name: values[i] for name, values in columns.items()} for i in range(batch.num_rows))
    last = max(row["episode"] for (part, _), held in rows.items() if part == DISC for row in held)

    def of_last(part: str, first: int) -> list[dict]:
        return sorted((r for r in rows.get((part, first), []) if r["episode"] == last),
                      key=lambda r: r["tick"])

    firsts = sorted(holds)
    agents = np.concatenate([of_last(DISC, f)[-1]["Points2D:positions"] for f in firsts])
    goals = np.concatenate([of_last(GOAL, f)[-1]["Boxes2D:centers"] for f in firsts])
    end = max(r["tick"] for f in firsts for r in of_last(DISC, f))  # the episode's end tick
    origins, vectors, who, ages = [], [], [], []
    for first in firsts:
        for row in of_last(INTENT, first):
            for i, (o, v) in enumerate(zip(row["Arrows2D:origins"], row["Arrows2D:vectors"])):
                if v[0] or v[1]:
                    origins.append(o), vectors.append(v), who.append(int(holds[first][i]))
                    ages.append(end - 1 - row["tick"])
    waits = [(o, v) for first in firsts for row in of_last(WAITS, first)
             for o, v in zip(row.get("Arrows2D:origins") or [], row.get("Arrows2D:vectors") or [])]
    return Episode(np.array(agents), np.array(goals),
                   (np.array(origins), np.array(vectors), np.array(who, int)),
                   (np.array([o for o, _ in waits]).reshape(-1, 2),
                    np.array([v for _, v in waits]).reshape(-1, 2)), np.array(ages, int))


def check_world(image: np.ndarray, config, run_dir: Path) -> dict:
    """Everything the world view must show of a run's newest episode, the one the viewer opens
    on (``config``: the run's ``SwarmConfig``): the grid, every wall, a label under each agent
    and goal, each agent in its own colour and its goal box on its cell, the moves announced and
    the waits. Raises
    AssertionError saying what is missing."""
    from nnql_swarm.recording.agent_entities import crowded
    from nnql_swarm.recording.fading import FRESH_STEPS
    from nnql_swarm.recording.palette import WAIT_COLOUR, WALL_COLOUR, agent_colors
    from nnql_swarm.recording.world import INTENT_SCALE

    grid = find_grid(image, config.width, config.height)
    episode = last_episode(run_dir / "run.rrd", config.n_agents)
    colours = agent_colors(config.n_agents)
    found = {"grid": grid}
    walls = config.walls()
    if len(walls):
        free = sorted({(x, y) for x in range(config.width) for y in range(config.height)}
                      - {tuple(cell) for cell in walls.tolist()})
        found["walls"] = check_walls(image, grid, walls, free, WALL_COLOUR)
    found["labels"] = check_labels(image, grid, np.concatenate([episode.agents, episode.goals]),
                                   np.concatenate([colours, colours]))
    found["colours"] = check_colours(image, grid, colours)
    found["on cells"] = check_goals_on_cells(image, grid, episode.goals, colours)
    origins, vectors, who = episode.moves
    if crowded(config.n_agents):  # the paths alone, the newest steps opaque (recording.fading)
        steps = vectors / INTENT_SCALE
        # The newest steps end where the agents stand: those under an agent's disc and label
        # (within a cell of where an agent ended) cannot show.
        middles = origins + steps / 2
        apart = np.abs(middles[:, None] - episode.agents[None]).max(axis=2).min(axis=1)
        fresh = (episode.ages < FRESH_STEPS // 2) & (apart > 1.0)
        found["paths"] = check_arrows(image, grid, origins[fresh], steps[fresh],
                                      colours[who[fresh]])
        return found
    found["moves"] = check_arrows(image, grid, origins, vectors, colours[who])
    origins, vectors = episode.waits
    if len(origins):  # an episode in which nobody waited has no such arrows
        found["waits"] = check_arrows(image, grid, origins, vectors, [WAIT_COLOUR] * len(origins))
    return found


def check_layout(image: np.ndarray, config) -> Grid:
    """The designed first view (``recording.blueprint``), by where the world view is: the run's
    grid at the page's left edge, over a quarter of the page wide. Rerun's automatic layout,
    which the viewer falls back on without the blueprint, puts a small world view among a grid
    of equal panels. Raises AssertionError saying what it found."""
    grid = find_grid(image, config.width, config.height)
    x0, y0, x1, _ = grid.box
    width = image.shape[1]
    if x0 > 0.05 * width or x1 - x0 < 0.25 * width or y0 > 0.15 * image.shape[0]:
        raise AssertionError(f"not the designed layout: the grid spans x {x0}..{x1}, y from "
                             f"{y0}, of a page {width} wide (the world view is at the left, "
                             f"over a quarter of the page)")
    return grid


def goal_centres(image: np.ndarray, grid: Grid, goals, colours, reach: float = 3.0,
                 least: float = 0.4) -> np.ndarray:
    """Where each agent's goal box is drawn, in cells of ``grid`` (``(k, 2)``, NaN where none
    is found): within ``reach`` cells of where its cell (``goals``) is on the grid, the place
    where the box's outline in the agent's colour (``colours``, ``(k, 3)``; the top and the
    sides: its label's pill covers the bottom) best matches the pixels of that colour, and a
    band just outside it least (the agent's path, as wide as the outline's band, matches along
    it as well, but not only inside), if the share of the outline inked less that of the band
    outside is at least ``least``."""
    from scipy import ndimage

    from nnql_swarm.recording.world import GOAL_HALF, GOAL_LINE

    half, line = GOAL_HALF * grid.cell, max(GOAL_LINE * grid.cell, 1.0)
    size = 2 * round(half + line + 0.2 * grid.cell) + 1
    yy, xx = np.mgrid[:size, :size] - size // 2
    ring = np.maximum(np.abs(xx), np.abs(yy)) - half
    upper = yy <= 0.5 * half
    outline = ((np.abs(ring) <= line) & upper).astype(np.float32)
    outside = ((ring > line + 1) & (ring <= line + 1 + 0.15 * grid.cell) & upper
               ).astype(np.float32)
    found = np.full((len(goals), 2), np.nan)
    for k, ((x, y), colour) in enumerate(zip(goals, colours)):
        cx, cy = cell_centre(grid, x, y)
        r = reach * grid.cell
        top, left = max(round(cy - r), 0), max(round(cx - r), 0)
        inked = near(image[top:round(cy + r) + 1, left:round(cx + r) + 1], colour,
                     12).astype(np.float32)
        score = (ndimage.correlate(inked, outline, mode="constant") / outline.sum()
                 - ndimage.correlate(inked, outside, mode="constant") / outside.sum())
        best = np.unravel_index(int(np.argmax(score)), score.shape)
        if score[best] >= least:
            found[k] = ((left + best[1] - grid.xs[0]) / grid.cell - 0.5,
                        (top + best[0] - grid.ys[0]) / grid.cell - 0.5)
    return found


def check_goals_on_cells(image: np.ndarray, grid: Grid, goals, colours, within: float = 0.15,
                         least: float = 0.6, seen_least: float = 0.3,
                         scale_within: float = 0.02) -> dict:
    """The agents' layer drawn where the grid says it is: of the goal boxes found
    (:func:`goal_centres`; at least ``seen_least`` of the agents': others' discs and labels
    cover some, and an agent's path can look like a box), at least ``least`` within ``within``
    of a cell of their cells, and the boxes drawn at the grid's scale within ``scale_within``
    (the median, over the boxes found 3 cells or more from the grid's centre, of how far from
    the centre each is drawn against how far its cell is). A view that draws the agents at
    another scale than the grid (Rerun's WebGL depth offsets, ``recording.agent_entities
    .GROUPED_FROM``) moves them off their cells the more the farther from the view's centre.
    Returns that scale, the share of boxes on their cells, how many were found and the
    median miss (in cells)."""
    goals = np.asarray(goals, float)
    drawn = goal_centres(image, grid, goals, colours)
    seen = ~np.isnan(drawn[:, 0])
    if seen.mean() < seen_least:
        raise AssertionError(f"the goal boxes of only {seen.sum()} of {len(goals)} agents "
                             f"found")
    miss = np.abs(drawn[seen] - goals[seen]).max(axis=1)
    centre = np.array([len(grid.xs) - 2, len(grid.ys) - 2]) / 2
    d, e = goals[seen] - centre, drawn[seen] - centre
    far = np.abs(d).max(axis=1) >= 3
    scale = float(np.median((d * e).sum(axis=1)[far] / (d * d).sum(axis=1)[far])) \
        if far.any() else 1.0
    on = float(np.mean(miss <= within))
    found = {"scale": round(scale, 4), "on cells": round(on, 3), "found": int(seen.sum()),
             "median miss": round(float(np.median(miss)), 3)}
    if on < least or abs(scale - 1) > scale_within:
        off = [(tuple(map(int, g)), tuple(np.round(p, 2)))
               for g, p, m in zip(goals[seen], drawn[seen], miss) if m > within]
        raise AssertionError(f"the agents' goal boxes drawn at {scale:.3f} of the grid's scale, "
                             f"{on:.0%} of the {seen.sum()} found on their cells (off: "
                             f"{off[:6]})")
    return found
