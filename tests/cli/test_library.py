"""The commands' typed, lazily imported library names: each one the real object, the typed
imports and the run-time table naming the same things."""

from __future__ import annotations

import ast
import importlib
import inspect

import pytest

from fieldcal.cli import library


def _typed_names() -> set[str]:
    """The names imported under ``if TYPE_CHECKING:`` in the module (what mypy sees)."""
    tree = ast.parse(inspect.getsource(library))
    block = next(
        n for n in tree.body if isinstance(n, ast.If) and "TYPE_CHECKING" in ast.dump(n.test)
    )
    return {
        alias.asname or alias.name
        for node in block.body
        if isinstance(node, ast.ImportFrom)
        for alias in node.names
    }


def test_typed_imports_and_runtime_table_name_the_same_things():
    assert _typed_names() == set(library.WHERE) == set(library.__all__)


@pytest.mark.parametrize("name", sorted(library.WHERE))
def test_each_name_is_the_library_object(name):
    module = importlib.import_module(library.WHERE[name], "fieldcal.cli")
    assert getattr(library, name) is getattr(module, name)


def test_a_patched_library_name_is_seen(monkeypatch):
    import fieldcal.pipeline

    def replaced(*args, **kwargs):
        raise AssertionError

    monkeypatch.setattr(fieldcal.pipeline, "run_log", replaced)
    assert library.run_log is replaced
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        library.nope  # noqa: B018
