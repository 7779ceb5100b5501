"""An independent reader of the planner's words: the sentence a person follows, back into a
rotation, for the tests (the planning tests and a simulated user of the live capture)."""

from __future__ import annotations

import re

import numpy as np

AXIS = {"X": 0, "Y": 1, "Z": 2}
_WORLD = {
    "north": np.array([1.0, 0.0, 0.0]),
    "east": np.array([0.0, 1.0, 0.0]),
    "south": np.array([-1.0, 0.0, 0.0]),
    "west": np.array([0.0, -1.0, 0.0]),
}
_HEADING = (
    r"(?:, \+([XYZ]) axis( \(its horizontal part\))? towards magnetic (north|east|south|west))?"
)
_FACE = re.compile(r"lying on a face: \+([XYZ]) axis pointing straight (down|up)" + _HEADING + "$")
_EDGE = re.compile(
    r"resting on an edge: ([+-][XYZ]) and ([+-][XYZ]) axes each 45° below the horizon, "
    r"([XYZ]) axis level" + _HEADING + "$"
)
_CORNER = re.compile(
    r"balanced on a corner: ([+-][XYZ]), ([+-][XYZ]) and ([+-][XYZ]) axes each 35° below the "
    r"horizon" + _HEADING + "$"
)


def _signed(token: str) -> np.ndarray:
    v = np.zeros(3)
    v[AXIS[token[1]]] = 1.0 if token[0] == "+" else -1.0
    return v


def parse_words(words: str) -> tuple[np.ndarray, np.ndarray | None]:
    """(down, rotation or None): the body's down direction and, when the words name a heading,
    the world → body rotation, reconstructed from the sentence alone."""
    if m := _FACE.match(words):
        down = np.eye(3)[AXIS[m[1]]] * (1.0 if m[2] == "down" else -1.0)
        tail = m.groups()[2:]
        assert tail[1] is None  # a face's named axis is horizontal: no "horizontal part"
    elif m := _EDGE.match(words):
        a, b = _signed(m[1]), _signed(m[2])
        assert a @ b == 0 and np.abs(a + b)[AXIS[m[3]]] == 0  # the level axis is the third
        down = (a + b) / np.sqrt(2.0)
        tail = m.groups()[3:]
        assert tail[0] in (None, m[3]) and tail[1] is None
    elif m := _CORNER.match(words):
        parts = [_signed(m[i]) for i in (1, 2, 3)]
        assert sorted(int(np.argmax(np.abs(p))) for p in parts) == [0, 1, 2]
        down = sum(parts) / np.sqrt(3.0)
        tail = m.groups()[3:]
        assert tail[0] is None or tail[1] is not None  # a tilted axis: its horizontal part
    else:
        raise AssertionError(f"unparsed words: {words!r}")
    axis, _, where = tail
    if axis is None:
        return down, None
    a = np.eye(3)[AXIS[axis]]
    h = a - (a @ down) * down
    h /= np.linalg.norm(h)
    # rotation taking the world triad (w, D, w × D) to the body triad (h, down, h × down)
    w, D = _WORLD[where], np.array([0.0, 0.0, 1.0])
    body = np.column_stack([h, down, np.cross(h, down)])
    world = np.column_stack([w, D, np.cross(w, D)])
    return down, body @ world.T
