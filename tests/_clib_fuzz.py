"""Drive the generated C library with operation scripts under AddressSanitizer and
UndefinedBehaviorSanitizer (tests/output/test_c_library_fuzz.py, benchmarks/fuzz_clib.py).

A small C driver (:data:`DRIVER`) keeps one calibration (the factory one to start), one
hard-iron estimator and one monitor, reads operations from stdin and prints one line per
operation: ``op rc state_finite cal_valid extra``. It states facts; the callers assert the
invariants: the estimator's and the monitor's state stay finite; a calibration only loads or
folds into a valid one; ``fieldcal_save`` writes exactly when ``fieldcal_check`` accepts, and
what it writes loads back bit for bit; a refused load leaves the calibration as it was; an
apply either succeeds with a finite result or fails with NaN.

The library and the driver are built with ``cc -std=c99 -fsanitize=address,undefined
-fno-sanitize-recover=all`` (any report aborts the run with a non-zero exit).
"""

from __future__ import annotations

import os
import shutil
import struct
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fieldcal.output.exports import export_files

SANITIZE = [
    "-fsanitize=address,undefined,float-cast-overflow",
    "-fno-sanitize-recover=all",
    "-fno-omit-frame-pointer",
]
CFLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-O1", "-g"]

# operations: code, then its payload (little-endian)
UPDATE, MONITOR, WIDEN, FOLD, SAVE, LOAD, APPLY, HEADING, HI_APPLY, INIT, TILT, POKE, FLAGS = range(
    13
)
NAMES = (
    "hardiron_update",
    "monitor_update",
    "hardiron_widen",
    "hardiron_fold",
    "save",
    "load",
    "apply",
    "heading",
    "hardiron_apply",
    "hardiron_init",
    "tilt",
    "poke a float",
    "poke the flags",
)

DRIVER = r"""
#include "fieldcal_cal.h"

#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>

static fieldcal_cal_t cal;
static fieldcal_hardiron_t hi;
static fieldcal_monitor_t mon;

static int rd(void *p, size_t n) { return fread(p, 1, n, stdin) == n; }

static int finite_n(const float *v, size_t n)
{
    size_t i;
    for (i = 0; i < n; i++) {
        if (!isfinite(v[i])) return 0;
    }
    return 1;
}

static int nan_n(const float *v, size_t n)
{
    size_t i;
    for (i = 0; i < n; i++) {
        if (!isnan(v[i])) return 0;
    }
    return 1;
}

static int state_finite(void)
{
    return finite_n(hi.beta, 3) && finite_n(hi.P, 9) && finite_n(hi.last_d, 3) &&
           finite_n(hi.last_m, 3) && isfinite(hi.field_norm) && isfinite(mon.sum_norm) &&
           isfinite(mon.sum_dip) && finite_n(mon.d2, FIELDCAL_MONITOR_WINDOW) &&
           isfinite(mon.statistic) && isfinite(mon.norm) && isfinite(mon.dip_deg);
}

static int outcome(const float *v, size_t n) { return finite_n(v, n) ? 1 : (nan_n(v, n) ? 0 : 2); }

int main(void)
{
    static uint8_t buf[4096], blob[FIELDCAL_BLOB_SIZE + 16];
    const size_t floats_at = offsetof(fieldcal_cal_t, accel_matrix);
    unsigned char op;
    float v[6];
    cal = FIELDCAL_FACTORY;
    fieldcal_monitor_init(&mon);
    printf("start %d %d\n", fieldcal_hardiron_init(&hi, &cal), fieldcal_check(&cal));
    while (rd(&op, 1)) {
        int rc = 0, extra = 0;
        switch (op) {
        case 0:
            if (!rd(v, sizeof v)) return 10;
            rc = fieldcal_hardiron_update(&hi, &cal, v, v + 3);
            break;
        case 1:
            if (!rd(v, sizeof v)) return 10;
            rc = fieldcal_monitor_update(&mon, &cal, v, v + 3);
            break;
        case 2:
            if (!rd(v, sizeof(float))) return 10;
            rc = fieldcal_hardiron_widen(&hi, v[0]);
            break;
        case 3:
            rc = fieldcal_hardiron_fold(&hi, &cal);
            break;
        case 4: {
            fieldcal_cal_t back;
            memset(&back, 0, sizeof back);
            rc = fieldcal_save(&cal, blob, sizeof blob);
            if (rc > 0) {
                const int l = fieldcal_load(&back, blob, (size_t)rc, cal.sensor_id);
                extra = l != FIELDCAL_OK ? l : (memcmp(&back, &cal, sizeof back) == 0 ? 1 : 2);
            }
            break;
        }
        case 5: {
            uint16_t len;
            uint32_t sid;
            fieldcal_cal_t before = cal;
            if (!rd(&sid, 4) || !rd(&len, 2) || len > sizeof buf || !rd(buf, len)) return 10;
            rc = fieldcal_load(&cal, buf, len, sid);
            extra = rc == FIELDCAL_OK || memcmp(&before, &cal, sizeof cal) == 0;
            break;
        }
        case 6: {
            unsigned char which;
            float out[3];
            if (!rd(&which, 1) || !rd(v, 3 * sizeof(float))) return 10;
            rc = which % 3 == 0 ? fieldcal_accel(&cal, v, out)
                 : which % 3 == 1 ? fieldcal_mag(&cal, v, out)
                                  : fieldcal_gyro(&cal, v, out);
            extra = outcome(out, 3);
            break;
        }
        case 7: {
            float h;
            if (!rd(v, sizeof v)) return 10;
            h = fieldcal_heading(&cal, v, v + 3);
            extra = isnan(h) ? 0 : (h >= 0.0f && h < 360.0f ? 1 : 2);
            break;
        }
        case 8:
            if (!rd(v, 3 * sizeof(float))) return 10;
            rc = fieldcal_hardiron_apply(&hi, v);
            extra = outcome(v, 3);
            break;
        case 9:
            rc = fieldcal_hardiron_init(&hi, &cal);
            break;
        case 10: {
            float r, p, t;
            if (!rd(v, 3 * sizeof(float))) return 10;
            t = fieldcal_tilt(v, &r, &p);
            extra = isnan(t) && isnan(r) && isnan(p)
                        ? 0
                        : (t >= 0.0f && t <= 180.0f && isfinite(r) && isfinite(p) ? 1 : 2);
            break;
        }
        case 11: {
            unsigned char index;
            if (!rd(&index, 1) || !rd(v, sizeof(float))) return 10;
            memcpy((unsigned char *)&cal + floats_at + sizeof(float) * (index % FIELDCAL_N_FLOATS),
                   v, sizeof(float));
            break;
        }
        case 12:
            if (!rd(&cal.flags, 4)) return 10;
            break;
        default:
            return 11;
        }
        printf("%u %d %d %d %d\n", op, rc, state_finite(), fieldcal_check(&cal) == FIELDCAL_OK,
               extra);
    }
    return 0;
}
"""


def sanitizers_missing(cc: str, folder: Path) -> str | None:
    """Why the sanitizers cannot be used with ``cc`` here, or None when they can."""
    probe = folder / "probe.c"
    probe.write_text("int main(void) { return 0; }\n")
    exe = folder / "probe"
    out = subprocess.run(
        [cc, *SANITIZE, str(probe), "-o", str(exe)], capture_output=True, text=True, check=False
    )
    if out.returncode != 0:
        return f"{cc} cannot build with -fsanitize=address,undefined: {out.stderr.strip()[:200]}"
    run = subprocess.run([str(exe)], capture_output=True, text=True, env=_env(), check=False)
    if run.returncode != 0:
        return f"a sanitized program does not run here: {run.stderr.strip()[:200]}"
    return None


def _env() -> dict[str, str]:
    return {
        **os.environ,
        # leak checking needs ptrace, which containers often forbid; memory errors still abort
        "ASAN_OPTIONS": "detect_leaks=0:abort_on_error=0:exitcode=86",
        "UBSAN_OPTIONS": "print_stacktrace=1:halt_on_error=1:exitcode=87",
    }


@dataclass(frozen=True)
class Step:
    """One operation's line: its code, return code, and the driver's facts after it."""

    op: int
    rc: int
    state_finite: bool
    cal_valid: bool
    extra: int


class Driver:
    """The driver built against one calibration's library, with the sanitizers."""

    def __init__(self, cal, folder: Path, cc: str | None = None) -> None:
        cc = cc or shutil.which("cc")
        if cc is None:
            raise RuntimeError("no C compiler (cc) on PATH")
        folder.mkdir(parents=True, exist_ok=True)
        for name, content in export_files(cal, "c-library").items():
            (folder / name).write_bytes(content)
        (folder / "driver.c").write_text(DRIVER)
        self.exe = folder / "driver"
        cmd = [cc, *CFLAGS, *SANITIZE, f"-I{folder}", str(folder / "driver.c")]
        cmd += [str(folder / "fieldcal_cal.c"), "-o", str(self.exe), "-lm"]
        out = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if out.returncode != 0:
            raise RuntimeError(out.stderr)

    def run(self, script: bytes, timeout: float = 60.0) -> tuple[tuple[int, int], list[Step]]:
        """Run one script; ``((init rc, check rc), steps)``. Raises on a sanitizer report."""
        out = subprocess.run(
            [str(self.exe)], input=script, capture_output=True, timeout=timeout, env=_env()
        )
        if out.returncode != 0:
            raise AssertionError(
                f"driver exit {out.returncode}: {out.stderr.decode(errors='replace')[-3000:]}"
            )
        first, *lines = out.stdout.decode().splitlines()
        _, init_rc, check_rc = first.split()
        steps = [Step(*(int(x) for x in line.split())) for line in lines]
        return (int(init_rc), int(check_rc)), steps


# ------------------------------------------------------------------------ encoding
def f32(*values: float) -> bytes:
    return np.asarray(values, dtype=np.float64).astype("<f4", casting="unsafe").tobytes()


def update(op: int, a, m) -> bytes:
    return bytes([op]) + f32(*a, *m)


def widen(std: float) -> bytes:
    return bytes([WIDEN]) + f32(std)


def load(blob: bytes, sensor_id: int) -> bytes:
    return bytes([LOAD]) + struct.pack("<IH", sensor_id, len(blob)) + blob


def apply(sensor: int, raw) -> bytes:
    return bytes([APPLY, sensor]) + f32(*raw)


def three(op: int, v) -> bytes:
    return bytes([op]) + f32(*v)


def poke(index: int, value: float) -> bytes:
    return bytes([POKE, index % 256]) + f32(value)


def flags(value: int) -> bytes:
    return bytes([FLAGS]) + struct.pack("<I", value % 2**32)


def check(steps: list[Step], start_valid: bool = True) -> dict[str, int]:
    """Assert the invariants over one run's steps; counts per operation and outcome."""
    counts: dict[str, int] = {}
    poked = not start_valid
    for i, s in enumerate(steps):
        where = f"step {i}: {NAMES[s.op]} {s}"
        assert s.state_finite, where
        if s.op in (POKE, FLAGS):
            poked = True
        elif s.op == LOAD:
            assert s.extra == 1, "a refused load changed the calibration: " + where
            poked = poked and s.rc != 0
        elif s.op == FOLD and s.rc == 0:
            poked = False
        if not poked:
            assert s.cal_valid, "the calibration became invalid: " + where
        if s.op == SAVE:
            assert (s.rc > 0) == s.cal_valid, "save and check disagree: " + where
            if s.rc > 0:
                assert s.extra == 1, "a saved blob does not load back as it was: " + where
        if s.op in (APPLY, HI_APPLY):
            assert s.extra == (1 if s.rc == 0 else 0), where
        if s.op in (HEADING, TILT):
            assert s.extra in (0, 1), where
        key = f"{NAMES[s.op]} -> {s.rc}"
        counts[key] = counts.get(key, 0) + 1
    return counts
