"""The package's front door (``fieldcal/__init__.py``): public names load on first use, so that
``import fieldcal`` and ``fieldcal --version`` start fast (issue 24, item 5)."""

from __future__ import annotations

import subprocess
import sys

import pytest

import fieldcal


def _loaded_after(code: str) -> set[str]:
    out = subprocess.run(
        [sys.executable, "-c", f"{code}\nimport sys; print(' '.join(sys.modules))"],
        capture_output=True,
        text=True,
        check=True,
    )
    return set(out.stdout.split())


def test_import_fieldcal_loads_no_numerical_module():
    loaded = _loaded_after("import fieldcal")
    heavy = ("numpy", "scipy", "click", "rich", "matplotlib", "pyarrow", "threadpoolctl")
    assert {m for m in loaded if m.split(".")[0] in heavy} == set()
    assert {m for m in loaded if m.startswith("fieldcal.")} <= {
        "fieldcal._aliases",
        "fieldcal._version",
    }


def test_version_loads_the_group_only():
    code = (
        "from fieldcal.cli import cli\n"
        "try:\n"
        "    cli(['--version'], prog_name='fieldcal')\n"
        "except SystemExit:\n"
        "    pass"
    )
    loaded = _loaded_after(code)
    heavy = {"fieldcal.api", "fieldcal.calibration", "fieldcal.settings", "fieldcal.methods"}
    heavy |= {"fieldcal.output", "scipy", "rich"}
    assert {m for m in loaded if m.endswith("_cmd") or m in heavy} == set()


def test_every_public_name_resolves_to_its_module():
    for name in fieldcal.__all__:
        value = getattr(fieldcal, name)
        assert value is not None, name
    assert fieldcal.calibrate.__module__ == "fieldcal.api"
    assert fieldcal.Calibration.__module__ == "fieldcal.calibration"
    assert fieldcal.metrics.__name__ == "fieldcal.metrics"  # a subpackage on first use
    assert set(fieldcal.__all__) <= set(dir(fieldcal))


def test_an_unknown_name_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        fieldcal.nope  # noqa: B018
    assert not hasattr(fieldcal, "_private")


def test_command_modules_load_when_the_commands_are_needed():
    from fieldcal import cli as package

    names = {m.__name__.rsplit(".", 1)[1] for m in package.COMMAND_MODULES}
    assert names == set(package.cli.command_modules)  # type: ignore[attr-defined]
    assert {"calibrate", "export", "demo", "store"} <= set(package.cli.commands)
