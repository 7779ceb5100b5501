"""The ``mat`` export: a MATLAB ``.mat`` file (version 5, :func:`scipy.io.savemat`).

The same numbers and convention as the ``matlab`` script (:mod:`.matlab`, MATLAB's
``magcal``): ``C = (D - b) * A`` with ``D`` N-by-3, ``b`` 1-by-3, ``A = inv(gain).'``. The file
holds ``A_<sensor>``, ``b_<sensor>`` (doubles, bit for bit) and the character arrays
``formula`` and ``provenance``, so ``load cal.mat`` states its own convention.
"""

from __future__ import annotations

import io

import numpy as np

from ...calibration import Calibration
from ...errors import InputError
from .common import TEMPERATURE_FORMULA, corrections, cubic, provenance, temperature_terms
from .matlab import FORMULA, TEMPERATURE_USAGE

__all__ = ["CONTENT", "FORMULA", "write", "write_bytes"]

CONTENT = (
    "binary MATLAB v5 file: `A_accel`, `b_accel`, `A_mag`, `b_mag` (and `A_gyro`, `b_gyro`), "
    "`formula`, `provenance`; as the `matlab` script (with temperature terms `T_<sensor>`, "
    "`c_<sensor>`, `temperature_formula`)"
)


def write_bytes(cal: Calibration) -> bytes:
    """The ``.mat`` file's bytes.

    Parameters
    ----------
    cal : Calibration

    Returns
    -------
    bytes
        A MATLAB version 5 file; ``scipy.io.loadmat`` or MATLAB's ``load`` reads it.
    """
    variables: dict[str, object] = {
        "formula": FORMULA,
        "provenance": "; ".join(["Sensor calibration written by fieldcal.", *provenance(cal)]),
    }
    for name, M, b in corrections(cal):
        variables[f"A_{name}"] = np.ascontiguousarray(M.T)
        variables[f"b_{name}"] = b.reshape(1, 3)
    terms = temperature_terms(cal)
    for name, model in terms:
        variables[f"T_{name}"] = np.array([[model.reference, *model.span]])
        variables[f"c_{name}"] = cubic(model)
    if terms:
        variables["temperature_formula"] = f"{TEMPERATURE_FORMULA}; {TEMPERATURE_USAGE}"
    buffer = io.BytesIO()
    # SciPy loads here, not when the registry is imported: --version and --help stay light
    from scipy.io import savemat

    savemat(buffer, variables, format="5", oned_as="row")
    return buffer.getvalue()


def write(cal: Calibration) -> str:
    """Refuse: a ``.mat`` file is binary, so it goes to a file (``-o cal.mat``).

    Raises
    ------
    InputError
        Always, after the checks every export makes (a singular gain is named first).
    """
    corrections(cal)
    raise InputError(
        "the mat format is a binary file: write it with -o FILE.mat (or use --format matlab "
        "for the text script)"
    )
