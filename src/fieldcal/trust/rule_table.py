"""The verdict's rule table: each reason code with its fixed level and message template (the
numbers filled in by :func:`fieldcal.trust.verdict.reason`). Each message names the cause and
the fix; ``docs/trust.md`` has one row per code, and each code has one owning check in
:mod:`.verdict` (``OWNER``).
"""

from __future__ import annotations

from ..verdicts import Level

__all__ = ["RULES"]

#: code -> (level, message template). Each message names the cause and the fix.
RULES: dict[str, tuple[Level, str]] = {
    "interference_unusable": (
        "fail",
        "the vehicle's {input} adds {share:.0%} of the Earth's field to the magnetometer at "
        "{peak:.3g} {unit} (above 60 %, ArduPilot's compassmot limit): {heading:.1f}° of heading "
        "error uncorrected, {corrected:.1f}° after correction; move the compass away from the "
        "power leads, ESCs and motors (a GPS/compass mast) or twist the power leads together",
    ),
    "interference": (
        "warn",
        "the vehicle's {input} adds {share:.0%} of the Earth's field to the magnetometer at "
        "{peak:.3g} {unit} (30-60 %, ArduPilot's compassmot grey zone): {heading:.1f}° of "
        "heading error uncorrected, {corrected:.1f}° after correction; load the compensation "
        "(COMPASS_MOT_*, CAL_MAG*_COMP), and better move the compass away from the power leads "
        "or twist them together",
    ),
    "interference_not_identifiable": (
        "warn",
        "the magnetometer's interference in {input} is not identifiable from this log: "
        "{missing}; no compensation is given",
    ),
    "not_converged": (
        "fail",
        "the optimiser did not converge ({detail}); record more orientations or raise the "
        "iteration limit",
    ),
    "degenerate": (
        "fail",
        "the poses barely determine the calibration (condition number {condition:.2g}); add "
        "poses with the body's {axis} axis pointing up and down",
    ),
    "too_many_rejected": (
        "fail",
        "{rejected} of {total} poses had to be dropped (more than a quarter); record the session "
        "again, away from iron and with the device held still",
    ),
    "unidentifiable": (
        "fail",
        "{flagged} further pose(s) disagree with the model but dropping them would leave too "
        "few to calibrate; record the session again, away from iron, device held still",
    ),
    "same_sensor": (
        "fail",
        "the magnetometer readings are an affine copy of the accelerometer's (relative residual "
        "{residual:.2g}); check that the magnetometer columns are not the accelerometer's",
    ),
    "not_rigid": (
        "fail",
        "the {sensor}'s pose means scatter about the best fit by {ratio:.1%} of the field beyond "
        "their noise; no rigid device at rest does that (pose labels mixing orientations, "
        "wrong columns, or motion): check the pose grouping and the columns",
    ),
    "unusable": (
        "fail",
        "the calibration is too uncertain to use (predicted {what} error {value}, more than "
        "{factor:g}x the {target} target); {record}",
    ),
    "accuracy": (
        "warn",
        "the predicted {what} error {value} is worse than the {target} target; {record} (or "
        "set the target with --target-{option})",
    ),
    "untested": (
        "warn",
        "the fit certificate has {dof} degree(s) of freedom, too few ({minimum} or more) to "
        "test the model or find a disturbed pose; record {more} more pose(s) ({needed} in all)",
    ),
    "implausible_gain": (
        "warn",
        "the {sensor}'s gain is implausible for its sensor class ({what} {value:.3g}, more than "
        "{limit:.0%} off {expected}); check the columns, the units (--{option}) and that the "
        "device was still and rigid in every pose",
    ),
    "rejected": (
        "warn",
        "{count} pose(s) dropped as disturbed ({which}); see `rejected` for each and why",
    ),
    "trimmed": (
        "warn",
        "{share:.0%} of the {sensor}'s samples were cut as not still ({poses} poses); rows of "
        "another orientation inside a pose, or motion at the pose edges: check the pose "
        "labels or shorten the still intervals",
    ),
    "pose_noise": (
        "warn",
        "the {sensor}'s pose-to-pose error is {ratio:.1f}x its per-sample noise: "
        "poses not really still, or a magnetically busy site; rest the device on a firm "
        "support away from iron",
    ),
    "coverage": (
        "warn",
        "the recording covers the orientations poorly (the body's {axis} axis rarely points up "
        "or down); add such orientations for a better calibration",
    ),
    "negative_dip": (
        "note",
        "the dip came out negative ({dip:.1f}°): right in the southern magnetic hemisphere; "
        "otherwise the magnetometer is mirrored (--mag-mirrored) or the accelerometer reports "
        "gravity instead of specific force (--accel-sign gravity)",
    ),
    "reference_mirrored": (
        "warn",
        "the magnetometer came out mirrored relative to the accelerometer to match the "
        "{model}'s dip at {place} ({expected:+.1f}°): if it is (as on an LSM9DS1), state "
        "--mag-mirrored; if it is not, the accelerometer reports gravity instead of specific "
        "force (--accel-sign gravity), or --location is in the wrong hemisphere",
    ),
    "reference_unmirrored": (
        "warn",
        "--mag-mirrored was stated, but the {model}'s dip at {place} ({expected:+.1f}°) makes "
        "the magnetometer right-handed relative to the accelerometer, and the reference decided: "
        "drop --mag-mirrored, or check --accel-sign and --location",
    ),
    "reference_undecided": (
        "note",
        "the dip at {place} ({expected:+.1f}° in the {model}, fitted {dip:+.1f}°) is too close "
        "to 0° to tell a mirrored magnetometer; its handedness follows --mag-mirrored",
    ),
    "reference_dip": (
        "warn",
        "the fitted dip {dip:.2f} ± {std:.2f}° differs from the {model}'s {expected:.2f} ± "
        "{ref_std:.2f}° at {place} on {date} by {diff:.1f}°, more than 3σ plus the "
        "{allowance:g}° allowed for local anomalies: a disturbed site (steel, magnets, "
        "electronics, reinforced concrete: calibrate outdoors away from them), a wrong "
        "--location or --date, an accelerometer reporting gravity (--accel-sign gravity) or a "
        "mirrored magnetometer (--mag-mirrored)",
    ),
    "not_ml": (
        "warn",
        "the {method} estimate's likelihood is far below the optimum (J exceeds the maximum "
        "likelihood fit's by {excess:.3g}, χ²({dof}) p = {p:.2g}); the mle method would be more "
        "accurate",
    ),
    "correlated_poses": (
        "note",
        "the poses are consecutive pieces of one continuous motion: neighbouring poses' "
        "residuals are correlated (τ = {tau:.3g} poses, about {effective:.0f} independent of "
        "{poses}), so the error bars are widened {widening:.2g}x and the fit certificate is "
        "not a test of the model; rests (still detection) give a real test",
    ),
    "temperature_span": (
        "note",
        "the log's temperatures span {span:.1f} K ({low:.1f} to {high:.1f} °C): temperature "
        "terms need at least {need:g} K (power the board on cold and record while it warms); "
        "calibrated at the mean temperature {mean:.1f} °C",
    ),
    "implausible": (
        "warn",
        "the fit is implausible under the stated noise (J = {cost:.4g} for χ²({dof}), p = "
        "{p:.2g}); let fieldcal estimate the pose-level noise (pose noise auto)",
    ),
    "gyro_gain": (
        "warn",
        "the gyroscope's gain is implausible for a MEMS gyroscope ({what} {value}, limit "
        "{limit}); check the gyroscope's unit (rad/s: deg/s reads 57.3 times too much, "
        "--gyro-unit), its columns and axes (--gyro-cols), and that the log's time is in seconds",
    ),
    "gyro_segments": (
        "note",
        "{left_out} of {total} motion segments were left out of the gyroscope's fit: their "
        "integrated turn disagrees with the poses' (a bump, a gap in the log, or time stamps "
        "that are not the samples' own)",
    ),
    "gyro_misfit": (
        "note",
        "the gyroscope's motion segments disagree with its model beyond their noise (p = "
        "{p:.2g}); its error bars are widened {widening:.3g}x: check the time column and that "
        "the device was turned, not shaken, between the poses",
    ),
    "continuous_undetermined": (
        "fail",
        "{advice}",
    ),
    "continuous_unsettled": (
        "fail",
        "the fit left {which} undetermined although the log turned through them: the fit did "
        "not settle (check that the time column is in seconds, the gyroscope in rad/s, and "
        "that the log is not decimated below the motion's bandwidth)",
    ),
    "continuous_disturbed": (
        "note",
        "{disturbed:.3g} s of {duration:.3g} s were down-weighted for body acceleration (the "
        "hand's translation, beyond the lever arm's share); slower, smoother turns with less "
        "travel of the hand",
    ),
    "dropped_lines": (
        "warn",
        "{dropped} of {total} data lines ({share:.1%}) were dropped as unreadable ({which}); "
        "the samples between are missing: check the cable, the baud rate and that the device "
        "writes whole lines",
    ),  # continuous logs (fieldcal.trust.continuous_motion): gyroscope, field, turns
    "continuous_field_disturbed": (
        "fail",
        "the calibrated magnetic field's strength varies by {strength:.1%} RMS over the log "
        "(more than {limit:.0%}; dip spread {dip:.1f}° over {stretch:g}-s stretches): a "
        "magnet or iron that moves relative to the sensor, or a disturbed site; move away from "
        "the magnet (fix it rigidly or remove it) and record again",
    ),
    "gyro_units": (
        "fail",
        "the gyroscope's rates are {ratio:.3g}x the turning the magnetometer's direction shows "
        "(about 1 for rad/s, 57 for °/s): give the gyroscope in rad/s (°/s x 0.01745)",
    ),
    "gyro_gain_sign": (
        "fail",
        "the gyroscope's {axes} ax{plural} turned against the field sensors (gain {values}): "
        "an axis sign or mapping is wrong; check the gyroscope's columns and axis signs",
    ),
    "gyro_gain_scale": (
        "fail",
        "the gyroscope's scale came out {scale:.3g} (more than {limit:.0%} off 1 for rates in "
        "rad/s): check its units (rad/s) and columns",
    ),
    "gyro_misalignment": (
        "warn",
        "the gyroscope's {axis} axis is {angle:.2g} ± {std:.2g}° off the accelerometer's (more "
        "than {limit:g}°): mounted askew or a cross-axis error; check the axis mapping, or "
        "apply the fitted gain",
    ),
    "gyro_undetermined": (
        "note",
        "the log cannot determine the gyroscope's {axis} axis alignment to better than "
        "{std:.2g}° (1σ): turn about {axis} at a steady rate, then about the other axes",
    ),
    "continuous_fast_turns": (
        "warn",
        "the turns reach {rate:.3g} rad/s ({step:.2g} rad per sample{clipped}): the lever arm "
        "and the hand's translation grow with the rate and a sampled turn loses accuracy; "
        "slower turns",
    ),
    "unexplained_scale": (
        "warn",
        "the {sensor}'s gain is {scale:.3g} raw units per {unit}: no physical unit explains "
        "that (expected {low:g} to {high:g}); check that the columns hold the sensor's readings "
        "and how they were scaled",
    ),
    "temperature_ignored": (
        "warn",
        "the temperature column {column!r} was not used ({why}); the calibration has no "
        "temperature terms: give the column in °C, or leave --temp-col out",
    ),
}
