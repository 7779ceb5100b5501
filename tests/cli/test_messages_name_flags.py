"""Every error a command can reach names the command line's flag, never only the library's
keyword: a message that says ``split_on_reset=True`` says ``--split-on-reset`` too."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import fieldcal
from fieldcal.settings import OPTIONS

SRC = Path(fieldcal.__file__).parent
#: A Python keyword argument spelled out in a message: ``name=True``, ``name='x'``, ``name=3``.
KEYWORD = re.compile(r"\b([a-z][a-z0-9_]*)=(True|False|None|'[^']*'|\"[^\"]*\"|\d)")
#: Exceptions a command turns into its ``Error:`` line.
RAISED = {"InputError", "ValueError"}
#: Messages only the Python API reaches (arrays passed to fieldcal.calibrate), by file.
LIBRARY_ONLY = {"api.py": "per-pose input", "stats/pose_stats.py": "pass a list"}


def _text(node: ast.expr) -> str:
    """A message's literal text (an f-string's constant parts, ``+`` joined pieces)."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.JoinedStr):
        return "".join(
            _text(v) if not isinstance(v, ast.FormattedValue) else "{}" for v in node.values
        )
    if isinstance(node, ast.BinOp):
        return _text(node.left) + _text(node.right)
    if isinstance(node, ast.IfExp):
        return _text(node.body) + " " + _text(node.orelse)
    return ""


def _messages() -> list[tuple[str, int, str]]:
    """``(file, line, text)`` of each message raised as an error a user can cause."""
    found = []
    for path in sorted(SRC.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if not isinstance(node, ast.Raise) or not isinstance(node.exc, ast.Call):
                continue
            func = node.exc.func
            name = func.id if isinstance(func, ast.Name) else getattr(func, "attr", "")
            if name in RAISED and node.exc.args:
                text = _text(node.exc.args[0])
                found.append((str(path.relative_to(SRC)), node.lineno, text))
    return found


def _flags(keyword: str) -> list[str]:
    option = OPTIONS.get(keyword)
    if option is None or not option.on_command_line:
        return []
    return [f.split("/")[0] for f in option.flag.split("/")] + option.flag.split("/")


def test_the_scan_sees_the_messages():
    """The scan reads the messages it checks (a scan that found none could never fail)."""
    texts = [t for _, _, t in _messages()]
    assert len(texts) > 200
    assert any("split_on_reset=True" in t for t in texts)


def test_a_keyword_in_a_message_comes_with_its_flag():
    missing = []
    for file, line, text in _messages():
        for match in KEYWORD.finditer(text):
            flags = _flags(match.group(1))
            if LIBRARY_ONLY.get(file, "\0") in text:
                continue
            if flags and not any(flag in text for flag in flags):
                missing.append(f"{file}:{line}: {match.group(0)} without {flags[0]}")
    assert not missing, "\n".join(missing)
