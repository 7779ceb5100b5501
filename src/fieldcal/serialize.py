"""The versioned JSON form of frozen result dataclasses, written and read by walking their fields.

Each field is named once, in its dataclass. Field metadata says what the walker needs:
``shape`` (an array's shape, ``-1`` for any length), ``key`` (a JSON key other than the field
name), ``stored=False`` (derived, not written). A class may list ``JSON_DERIVED`` attribute
names written for human readers (standard errors, the dip) and ignored when reading.

Reading validates completely (types, shapes, finiteness, booleans that are booleans) and names
the first problem in one line, so nothing downstream sees a malformed document. Numbers are
written exactly (``repr`` round trip); NaN and infinity as the strings ``"nan"``, ``"inf"``.
"""

from __future__ import annotations

import dataclasses
import json
import math
import types
import typing
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, SupportsFloat, TypeAlias, TypeVar, cast

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

__all__ = ["SCHEMA", "SCHEMA_VERSION", "decode", "dumps", "encode", "upgrade"]

SCHEMA = "fieldcal.calibration"
#: 2: derived values (standard errors, cost) are no longer read back; pose-level noise,
#: verdict, rejected poses and accuracy added. 3: each verdict reason is an object
#: ``{"code", "level", "text"}`` (it was a sentence). 4: each sensor may carry ``temperature``
#: (its bias against temperature; absent: none). Older documents still load.
SCHEMA_VERSION = 4

_MAX_POSES = 10_000_000

_D = TypeVar("_D", bound="DataclassInstance")
#: A JSON array of numbers, nested to any depth.
_Nested: TypeAlias = "float | list[_Nested]"


def _number(value: SupportsFloat) -> float | str:
    value = float(value)
    if math.isnan(value):
        return "nan"
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    return value


def encode(value: object) -> object:
    """A JSON-ready form of ``value``: dataclasses as dicts of their stored fields (plus their
    ``JSON_DERIVED`` values), arrays as nested lists, NaN/inf as strings."""
    if type(value) is float:  # the common leaf first: a document holds about a thousand numbers
        return value if math.isfinite(value) else _number(value)
    kind = type(value)
    if value is None or kind is str or kind is int or kind is bool:
        return value
    if isinstance(value, str):
        return value
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        out: dict[str, object] = {}
        for f in dataclasses.fields(value):
            if f.metadata.get("stored", True):
                out[f.metadata.get("key", f.name)] = encode(getattr(value, f.name))
        for name in getattr(value, "JSON_DERIVED", ()):
            out[name] = encode(getattr(value, name))
        return out
    if isinstance(value, np.ndarray):
        if value.dtype.kind == "f" and np.isfinite(value).all():
            return value.tolist()  # Python floats already: no walk over the entries
        if value.dtype.kind in "fc":
            return encode(value.tolist())
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [encode(v) for v in value]
    if isinstance(value, Mapping):
        return {str(k): encode(v) for k, v in value.items()}
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return _number(value)
    return str(value)


#: One JSON encoder for the leaves of :func:`dumps` (``json.dumps`` with an option makes one a call)
_LEAF = json.JSONEncoder(allow_nan=False).encode


def dumps(value: object, indent: int | None = 2) -> str:
    """JSON text of an :func:`encode`-d document laid out for reading: an object one key per
    line, a list of numbers or words on one line, a list of lists or objects one item per line
    (a matrix one row per line, each row from one call of the json module's C encoder). The
    same document as ``json.dumps(value, indent=indent)`` in about a quarter of the lines, and
    somewhat faster (1.4 against 1.7 ms for a Table 1 calibration). ``indent=None``: all on
    one line, as ``json.dumps(value)``."""
    if indent is None:
        return _LEAF(value)
    parts: list[str] = []
    _lay_out(value, 0, indent, parts)
    return "".join(parts)


def _lay_out(value: object, level: int, indent: int, out: list[str]) -> None:
    inner = "\n" + " " * (indent * (level + 1))
    if isinstance(value, dict) and value:
        flat = _flat_record(value, level, indent)
        if flat is not None:
            out.append(flat)
            return
        sep = "{"
        for key, item in value.items():
            out.append(f"{sep}{inner}{_LEAF(str(key))}: ")
            _lay_out(item, level + 1, indent, out)
            sep = ","
        out.append("\n" + " " * (indent * level) + "}")
    elif isinstance(value, list) and any(isinstance(v, (list, dict)) for v in value):
        fast = _matrices(value, level, indent)
        if fast is not None:
            out.append(fast)
            return
        if all(isinstance(v, list) for v in value):
            text = _LEAF(value)
            if '"' not in text and "[[[" not in text:  # rows of numbers: one row a line
                rows = text[1:-1].replace("], [", "]," + inner + "[")
                out.append(f"[{inner}{rows}\n{' ' * (indent * level)}]")
                return
        sep = "["
        for item in value:
            out.append(sep + inner)
            _lay_out(item, level + 1, indent, out)
            sep = ","
        out.append("\n" + " " * (indent * level) + "]")
    else:
        out.append(_LEAF(value))


def _flat_record(value: dict[object, object], level: int, indent: int) -> str | None:
    """:func:`_lay_out`'s text of a flat object (a row of the pose table: thousands in samples
    mode) from one call of the C encoder, or None when it is not one: every entry a number,
    null, boolean or list of them, no string (so the only quotes are the keys', and ``, "``
    occurs only between entries)."""
    for entry in value.values():
        if isinstance(entry, (str, dict)) or (
            isinstance(entry, list) and any(isinstance(v, (str, list, dict)) for v in entry)
        ):
            return None
    text = _LEAF(value)
    if text.count('"') != 2 * len(value):  # a key with a quote or escape in it: the general path
        return None
    pad = "\n" + " " * (indent * (level + 1))
    return (
        "{" + pad + text[1:-1].replace(', "', "," + pad + '"') + "\n" + " " * (indent * level) + "}"
    )


def _matrices(value: list[object], level: int, indent: int) -> str | None:
    """:func:`_lay_out`'s text of a list of matrices of numbers (every pose's rotation) from
    one call of the C encoder, or None when it is not one (each item a non-empty list of
    non-empty lists of numbers, booleans or nulls)."""
    for item in value:
        if not isinstance(item, list) or not item:
            return None
        for row in item:
            if not isinstance(row, list) or not row:
                return None
            if any(isinstance(x, (str, list, dict)) for x in row):
                return None
    text = _LEAF(value)
    outer, item_pad, row_pad = (" " * (indent * k) for k in (level, level + 1, level + 2))
    body = (
        text[3:-3]
        .replace("]], [[", f"]\n{item_pad}],\n{item_pad}[\n{row_pad}[")
        .replace("], [", f"],\n{row_pad}[")
    )
    return f"[\n{item_pad}[\n{row_pad}[{body}]\n{item_pad}]\n{outer}]"


# ----------------------------------------------------------------------------- reading
def _fail(where: str, what: str) -> typing.NoReturn:
    raise ValueError(f"invalid calibration file: {where} {what}; write it again with fieldcal")


def _float(value: object, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        _fail(where, f"must be a number, not {type(value).__name__}")
    if isinstance(value, str):
        if value not in ("nan", "inf", "-inf"):
            _fail(where, f"must be a number, not the text {value[:20]!r}")
        return float(value)
    try:
        return float(value)
    except OverflowError:  # an integer of hundreds of digits
        _fail(where, "is too large a number")


#: Deepest nesting of lists and objects in free-form values (options, pose rows).
_MAX_DEPTH = 32


def _plain(value: object, where: str, depth: int = 0) -> object:
    """A free-form JSON value (an option, a pose row) checked to nest at most
    :data:`_MAX_DEPTH` deep, so writing it again cannot exhaust the stack."""
    if depth > _MAX_DEPTH:
        _fail(where, "is nested too deeply")
    if isinstance(value, dict):
        return {k: _plain(v, where, depth + 1) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain(v, where, depth + 1) for v in value]
    return value


def _array(value: object, where: str, shape: tuple[int, ...] | None) -> NDArray[np.float64]:
    def walk(v: object, depth: int) -> _Nested:
        if isinstance(v, list):
            if depth > 4:
                _fail(where, "is nested too deeply")
            return [walk(x, depth + 1) for x in v]
        return _float(v, where)

    if not isinstance(value, list):
        _fail(where, f"must be a list of numbers, not {type(value).__name__}")
    numbers = walk(value, 0)
    try:
        array = np.array(numbers, dtype=float)
    except ValueError:
        _fail(where, "has rows of different lengths")
    if shape is not None:
        ok = array.ndim == len(shape) and all(
            want in (-1, got) for want, got in zip(shape, array.shape, strict=True)
        )
        if not ok and not (array.size == 0 and shape[0] == -1):
            wanted = "x".join("N" if s == -1 else str(s) for s in shape)
            _fail(where, f"must have shape {wanted}, got {list(array.shape)}")
        if array.size == 0 and shape[0] == -1:
            array = array.reshape((0, *[max(s, 0) for s in shape[1:]]))
    return array


def _is_array_hint(hint: object) -> bool:
    return typing.get_origin(hint) is np.ndarray or hint is np.ndarray


def _decode_value(hint: object, value: object, where: str, meta: Mapping[str, object]) -> object:
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        if value is None:
            return None
        return _decode_value(args[0], value, where, meta)
    if _is_array_hint(hint):
        return _array(value, where, cast("tuple[int, ...] | None", meta.get("shape")))
    if isinstance(hint, type) and dataclasses.is_dataclass(hint):
        return decode(hint, value, where)
    if hint is float:
        return _float(value, where)
    if hint is bool:
        if not isinstance(value, bool):
            _fail(where, f"must be true or false, not {value!r}"[:120])
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            _fail(where, f"must be a whole number, not {value!r}"[:120])
        return value
    if hint is str:
        if not isinstance(value, str):
            _fail(where, f"must be text, not {type(value).__name__}")
        return value
    if origin is tuple:
        if not isinstance(value, list):
            _fail(where, f"must be a list, not {type(value).__name__}")
        item = typing.get_args(hint)[0]
        if len(value) > _MAX_POSES:
            _fail(where, "is too long")
        return tuple(_decode_value(item, v, f"{where}[{i}]", {}) for i, v in enumerate(value))
    if origin is dict:
        if not isinstance(value, dict):
            _fail(where, f"must be an object, not {type(value).__name__}")
        if typing.get_args(hint)[1] is str:
            for k, v in value.items():
                if not isinstance(v, str):
                    _fail(f"{where}.{k}", "must be text")
        return _plain(value, where)
    return _plain(value, where)  # free-form (an untyped field): kept as read


def decode(cls: type[_D], data: object, where: str = "document") -> _D:
    """Build dataclass ``cls`` from ``data`` (as written by :func:`encode`), validating every
    stored field; unknown keys (derived values, newer additions) are ignored."""
    if not isinstance(data, Mapping):
        _fail(where, f"must be an object, not {type(data).__name__}")
    hints = typing.get_type_hints(cls)
    kwargs: dict[str, object] = {}
    for f in dataclasses.fields(cls):
        if not f.metadata.get("stored", True):
            continue
        key = f.metadata.get("key", f.name)
        if key not in data:
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                _fail(where, f"has no {key!r}")
            continue
        kwargs[f.name] = _decode_value(hints[f.name], data[key], f"{where}.{key}", f.metadata)
    try:
        return cls(**kwargs)
    except (TypeError, ValueError) as exc:
        _fail(where, f"is not valid ({' '.join(str(exc).split())})")


# ----------------------------------------------------------------------------- versions
def _v1_to_v2(data: dict[str, object]) -> dict[str, object]:
    """fieldcal 0.1 wrote ``converged=False`` for an implausible fit and had no verdict: the
    optimiser's own flag is not recoverable, so an implausible v1 fit reads as converged with
    its certificate kept in ``diagnostics``."""
    out = dict(data)
    diag = out.get("diagnostics")
    if isinstance(diag, dict) and str(diag.get("status", "")).startswith("implausible"):
        out["converged"] = True
    return out


#: Schema 2's verdict sentences → (code, level): a fragment each rule's fixed message had
#: (fieldcal 0.2–0.3; frozen, as those files are). A sentence matching none becomes
#: ``other`` with the verdict's level.
_V2_REASONS: tuple[tuple[str, str, str], ...] = (
    ("the optimiser did not converge", "not_converged", "fail"),
    ("the poses barely determine the calibration", "degenerate", "fail"),
    ("(more than a quarter)", "too_many_rejected", "fail"),
    ("further pose(s) disagree with the model", "unidentifiable", "fail"),
    ("affine copy of the accelerometer", "same_sensor", "fail"),
    ("no rigid device at rest does that", "not_rigid", "fail"),
    ("too uncertain to use", "unusable", "fail"),
    ("dropped as disturbed", "rejected", "warn"),
    ("were cut as not still", "trimmed", "warn"),
    ("pose-to-pose error is", "pose_noise", "warn"),
    ("cover the orientations poorly", "coverage", "warn"),
    ("the dip came out negative", "negative_dip", "note"),
    ("came out mirrored relative to the accelerometer", "reference_mirrored", "warn"),
    ("--mag-mirrored was stated, but", "reference_unmirrored", "warn"),
    ("to tell a mirrored magnetometer", "reference_undecided", "note"),
    ("allowed for local anomalies", "reference_dip", "warn"),
    ("likelihood is far below the optimum", "not_ml", "warn"),
    ("the fit is implausible under the stated noise", "implausible", "warn"),
)


def _v2_reason(text: object, verdict_level: object) -> object:
    if not isinstance(text, str):
        return text  # left for the reader to refuse, naming the key
    for fragment, code, level in _V2_REASONS:
        if fragment in text:
            return {"code": code, "level": level, "text": text}
    plain = "note" if verdict_level == "pass" else verdict_level
    return {"code": "other", "level": plain, "text": text}


def _v2_to_v3(data: dict[str, object]) -> dict[str, object]:
    """Schema 2 stored the verdict's reasons as sentences: each becomes ``{code, level, text}``
    (:data:`_V2_REASONS`)."""
    out = dict(data)
    verdict = out.get("verdict")
    if isinstance(verdict, dict) and isinstance(verdict.get("reasons"), list):
        level = verdict.get("level")
        reasons = [_v2_reason(r, level) for r in verdict["reasons"]]
        out["verdict"] = {**verdict, "reasons": reasons}
    return out


def _v3_to_v4(data: dict[str, object]) -> dict[str, object]:
    """Schema 3 had no temperature models: a sensor without one reads as before."""
    return dict(data)


UPGRADES: dict[int, Callable[[dict[str, object]], dict[str, object]]] = {
    1: _v1_to_v2,
    2: _v2_to_v3,
    3: _v3_to_v4,
}


def upgrade(data: Mapping[str, object]) -> dict[str, object]:
    """Check the header and bring an older document to :data:`SCHEMA_VERSION`."""
    if data.get("schema") != SCHEMA:
        raise ValueError(
            f"not a fieldcal calibration (schema {str(data.get('schema'))[:40]!r}); "
            f"expected a file written by fieldcal with schema {SCHEMA!r}"
        )
    version = data.get("schema_version")
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise ValueError(
            f"invalid calibration file: schema_version {str(version)[:20]!r} is not a version "
            "number; write it again with fieldcal"
        )
    if version > SCHEMA_VERSION:
        raise ValueError(
            f"calibration schema version {version} is newer than this fieldcal understands "
            f"({SCHEMA_VERSION}); upgrade fieldcal"
        )
    out = dict(data)
    while version < SCHEMA_VERSION:
        out = UPGRADES[version](out)
        version += 1
    return out
