"""The colours of the recording: each agent's own (readable as a label on white, apart from
each other at any number of agents), the collisions', the waits' and the walls'."""

import numpy as np

COLLISION_RED = (230, 40, 40)
WAIT_COLOUR = (25, 25, 25)
"""The negotiation's arrows (who waited for whom): near-black, apart from the agents' colours."""
PUSH_COLOUR = (70, 40, 130)
"""Priority inheritance's pushes (``recording.world``: who made whom make way)."""
REACHED_COLOUR = (250, 200, 40)
"""A goal reached in a lifelong run, where it was."""
WALL_COLOUR = (55, 60, 75)
"""Walls: dark slate blocks, none of the agents' colours, and off the grid's grey."""

PALETTE = np.array([
    (0, 90, 181), (204, 80, 0), (0, 130, 60), (125, 50, 180), (190, 20, 120), (0, 120, 135),
    (135, 85, 20), (95, 105, 0), (40, 45, 140), (165, 0, 200), (150, 50, 90), (80, 80, 200),
], dtype=np.uint8)
"""The first twelve agents' colours: hues far apart, each dark enough for its label (coloured
text on the viewer's light label background) to read, at a contrast of 4.4 to 11 against white,
and none near the collisions' red. Beyond twelve agents :func:`agent_colors` adds more."""

LABEL_LIGHTNESS = (25.0, 49.0)
"""CIE L* of the colours added beyond :data:`PALETTE`: at most 49, a contrast of at least 4.5
against white, so that a label in that colour reads; at least 25, apart from the waits' black."""

KEEP_APART = ((COLLISION_RED, 60), (WAIT_COLOUR, 60), (WALL_COLOUR, 40), ((90, 90, 90), 30))
"""Colours an agent's must stay away from (most channel difference), so that no agent is read as
a collision, a wait, a wall or the grid: the collisions' red, the waits, the walls, the grid."""


def _lab_to_rgb(lab: np.ndarray) -> np.ndarray:
    """CIE L*a*b* (D65) to sRGB in [0, 1], unclipped (outside [0, 1]: out of gamut)."""
    fy = (lab[:, 0] + 16.0) / 116.0
    f = np.stack([fy + lab[:, 1] / 500.0, fy, fy - lab[:, 2] / 200.0], axis=1)
    xyz = np.where(f > 6 / 29, f ** 3, 3 * (6 / 29) ** 2 * (f - 4 / 29)) * [0.95047, 1.0, 1.08883]
    linear = xyz @ np.array([[3.2406, -0.9689, 0.0557], [-1.5372, 1.8758, -0.2040],
                             [-0.4986, 0.0415, 1.0570]])
    return np.where(linear <= 0.0031308, 12.92 * linear,
                    1.055 * np.abs(linear) ** (1 / 2.4) - 0.055)


def _rgb_to_lab(rgb: np.ndarray) -> np.ndarray:
    """sRGB bytes to CIE L*a*b* (D65)."""
    c = np.asarray(rgb, dtype=np.float64) / 255.0
    linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    xyz = linear @ np.array([[0.4124, 0.2126, 0.0193], [0.3576, 0.7152, 0.1192],
                             [0.1805, 0.0722, 0.9505]]) / [0.95047, 1.0, 1.08883]
    f = np.where(xyz > (6 / 29) ** 3, np.cbrt(xyz), xyz / (3 * (6 / 29) ** 2) + 4 / 29)
    return np.stack([116 * f[:, 1] - 16, 500 * (f[:, 0] - f[:, 1]), 200 * (f[:, 1] - f[:, 2])],
                    axis=1)


def _candidates() -> np.ndarray:
    """Every colour :func:`agent_colors` may add: a lattice of L*a*b* within
    :data:`LABEL_LIGHTNESS`, in the sRGB gamut, away from :data:`KEEP_APART`."""
    lightness, a, b = np.meshgrid(np.arange(LABEL_LIGHTNESS[0], LABEL_LIGHTNESS[1] + 1, 4.0),
                                  np.arange(-80.0, 81.0, 5.0), np.arange(-80.0, 81.0, 5.0),
                                  indexing="ij")
    rgb = _lab_to_rgb(np.stack([lightness.ravel(), a.ravel(), b.ravel()], axis=1))
    rgb = np.round(rgb[np.all((rgb >= 0) & (rgb <= 1), axis=1)] * 255).astype(np.uint8)
    keep = np.ones(len(rgb), dtype=bool)
    for colour, apart in KEEP_APART:
        keep &= np.abs(rgb.astype(int) - colour).max(axis=1) > apart
    return np.unique(rgb[keep], axis=0)


_COLOURS = [PALETTE]


def agent_colors(n: int) -> np.ndarray:
    """Each agent's colour as RGB bytes ``(n, 3)``, all different: :data:`PALETTE`, then, one
    at a time, the candidate (:func:`_candidates`) farthest in L*a*b* from every colour taken,
    so that each new colour is as distinct as it can be from those before (deterministic; an
    agent keeps its colour whatever the number of agents)."""
    taken = _COLOURS[0]
    if len(taken) < n:
        pool = _candidates()
        pool_lab = _rgb_to_lab(pool)
        nearest = np.min(np.linalg.norm(pool_lab[:, None] - _rgb_to_lab(taken)[None], axis=2),
                         axis=1)
        added: list[np.ndarray] = []
        while len(taken) + len(added) < n:
            k = int(nearest.argmax())
            added.append(pool[k])
            nearest = np.minimum(nearest, np.linalg.norm(pool_lab - pool_lab[k], axis=1))
        taken = _COLOURS[0] = np.concatenate([taken, np.array(added, dtype=np.uint8)])
    return taken[:n]
