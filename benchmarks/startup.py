"""Startup: ``fieldcal --version`` against ``python -c "import numpy"`` (issue 24, item 5).

Each round starts every command once, in turn (an interleaved A/B loop, so a busy machine slows
every row alike); the table gives the median wall time of each command over the rounds and its
ratio to the anchor, with the machine's load average before and after.

Every child runs with its bytecode cached (``PYTHONPYCACHEPREFIX`` in a temporary folder, warmed
by one untimed start of each command), as an installed package has it: a shell that sets
``PYTHONDONTWRITEBYTECODE=1`` would otherwise compile fieldcal's sources on every start while
numpy's come precompiled from its wheel.

Also lists the largest self times of ``python -X importtime -m fieldcal --version`` outside
numpy (one run): where what is left of the startup goes.

    python benchmarks/startup.py            # 30 rounds, writes the section of docs/benchmarks.md
    python benchmarks/startup.py --quick    # 8 rounds, prints only
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _report import stamp, write_section

#: The issue's target: ``fieldcal --version`` within this multiple of ``import numpy``.
TARGET_RATIO = 1.5


def commands() -> dict[str, list[str]]:
    """The anchor first, then fieldcal's starts (the console script when installed)."""
    rows = {
        'python -c "import numpy"': [sys.executable, "-c", "import numpy"],
        "python -m fieldcal --version": [sys.executable, "-m", "fieldcal", "--version"],
    }
    script = shutil.which("fieldcal")
    if script is not None:
        rows["fieldcal --version"] = [script, "--version"]
    rows['python -c "import fieldcal"'] = [sys.executable, "-c", "import fieldcal"]
    rows["python -m fieldcal --help"] = [sys.executable, "-m", "fieldcal", "--help"]
    return rows


def load() -> str:
    return ", ".join(f"{x:.2f}" for x in os.getloadavg())


def importtime(env: dict[str, str], top: int = 8) -> list[tuple[str, int]]:
    """The largest self times (µs) of ``--version``'s imports outside numpy."""
    out = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "fieldcal", "--version"],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    ).stderr
    rows = []
    for line in out.splitlines():
        parts = line.removeprefix("import time:").split("|")
        if len(parts) != 3 or not parts[0].strip().isdigit():
            continue
        name = parts[2].strip()
        if name.split(".")[0] != "numpy":
            rows.append((name, int(parts[0])))
    return sorted(rows, key=lambda r: -r[1])[:top]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="8 rounds, no docs update")
    args = parser.parse_args()
    rounds = 8 if args.quick else 30
    cmds = commands()
    with tempfile.TemporaryDirectory(prefix="fieldcal-pyc-") as cache:
        env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
        env["PYTHONPYCACHEPREFIX"] = cache
        for cmd in cmds.values():  # warm the bytecode cache and the disk cache
            subprocess.run(cmd, env=env, check=True, stdout=subprocess.DEVNULL)
        load_before = load()
        times: dict[str, list[float]] = {name: [] for name in cmds}
        for _ in range(rounds):
            for name, cmd in cmds.items():
                start = time.perf_counter()
                subprocess.run(cmd, env=env, check=True, stdout=subprocess.DEVNULL)
                times[name].append(time.perf_counter() - start)
        load_after = load()
        imports = importtime(env)
    anchor = statistics.median(next(iter(times.values())))
    lines = ["| command | median ms | × import numpy | target |", "|---|---|---|---|"]
    for name, values in times.items():
        med = statistics.median(values)
        target = f"≤ {TARGET_RATIO:g}×" if name.endswith("--version") else ""
        met = ""
        if target:
            met = " (met)" if med / anchor <= TARGET_RATIO else " (not met)"
        lines.append(f"| `{name}` | {1e3 * med:.0f} | {med / anchor:.2f} | {target}{met} |")
    slow = ["| module | self ms |", "|---|---|"]
    slow += [f"| `{module}` | {us / 1e3:.1f} |" for module, us in imports]
    text = (
        "## Startup\n\n"
        + stamp("python benchmarks/startup.py" + (" --quick" if args.quick else ""))
        + f"\nLoad average (1, 5, 15 min): {load_before} before, {load_after} after.\n\n"
        f"Interleaved A/B loop: {rounds} rounds, each starting every command once in turn; "
        "median wall time per command over the rounds, and its ratio to the anchor "
        '`python -c "import numpy"` of the same rounds. Bytecode cached for every child '
        "(`PYTHONPYCACHEPREFIX` in a temporary folder, warmed once), as an installed package "
        "has it. `import fieldcal` loads no numerical module (each public name loads its module "
        "on first use); `--version` loads numpy, click and the command group only (the command "
        "modules load when a command is first looked up, so `--help` pays for them).\n\n"
        + "\n".join(lines)
        + "\n\nLargest self times of `python -X importtime -m fieldcal --version` outside numpy "
        "(one run):\n\n" + "\n".join(slow) + "\n"
    )
    print(text)
    if not args.quick:
        write_section("startup", text)


if __name__ == "__main__":
    main()
