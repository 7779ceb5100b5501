"""What to add to a calibration from continuous motion, in command-line terms: ``fieldcal
plan`` has no still pose to add to it, so it names the orientations the motion never reached
and the axis it turned least about, and the command that calibrates the new recording."""

from __future__ import annotations

import math

import numpy as np

from ..calibration import Calibration

__all__ = ["REACHED_DEG", "more_motion_advice"]

#: An axis counts as having pointed up when the motion brought it within this angle of up.
REACHED_DEG = 30.0
_AXES = tuple((f"{sign}{name}", s * np.eye(3)[i]) for i, name in enumerate("xyz") for sign, s in
              (("+", 1.0), ("-", -1.0)))  # fmt: skip


def more_motion_advice(cal: Calibration) -> str:
    """One line: the turns a continuous calibration's recording lacks (axes never pointed up,
    the axis turned about least) and how to calibrate a new recording."""
    g = np.asarray(cal.gravity if cal.gravity is not None else (0.0, 0.0, -1.0), dtype=float)
    up = np.einsum("nij,j->ni", np.asarray(cal.rotations, dtype=float), g / np.linalg.norm(g))
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    reach = math.cos(math.radians(REACHED_DEG))
    missing = [name for name, axis in _AXES if not np.any(up @ axis > reach)]
    turned = dict((cal.options.get("trajectory") or {}).get("turned_deg") or {})
    parts = []
    if missing:
        parts.append(
            "turn it until each of these axes points up, for a few seconds each: "
            + ", ".join(missing)
            + f" (the motion never brought them within {REACHED_DEG:g}° of up)"
        )
    if turned:
        least = min(turned, key=lambda k: float(turned[k]))
        parts.append(
            f"turn it more about its {least} axis ({float(turned[least]):.0f}° in all, against "
            + ", ".join(f"{float(v):.0f}° about {k}" for k, v in turned.items() if k != least)
            + ")"
        )
    if not missing:
        parts.append("record longer: the predicted error falls as 1/√(seconds of motion)")
    return (
        "this calibration is from continuous motion: there is no still pose to add to it. "
        "Record the motion again, and " + "; ".join(parts) + "; then calibrate the new log "
        "with fieldcal calibrate LOG --poses continuous (or record still poses, each axis up "
        "and down, and plan with fieldcal plan on that calibration)"
    )
