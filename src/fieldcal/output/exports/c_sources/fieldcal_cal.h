/* fieldcal on a microcontroller: apply, keep, check and update a sensor calibration.
 *
@PROVENANCE@
 *
 * C99, float32, no dynamic memory; needs only <math.h>, <stdint.h>, <string.h> (link with -lm).
 * Frames and formulas are fieldcal's (docs/conventions.md, docs/microcontroller.md):
 *   body = M * (raw - b)  with M = inv(gain), b = bias, per sensor (one common body frame);
 *   the world frame is North-East-Down; at rest the accelerometer reads the specific force,
 *   "up" (|a| = g), and the field dips below the horizon by the dip angle.
 */
#ifndef FIELDCAL_CAL_H
#define FIELDCAL_CAL_H

#include <stdint.h>
#include <string.h>

/* ---- this calibration (generated) ---- */
@DEFINES@
/* Both files of a library carry this number; fieldcal_cal.c refuses to build with a header
 * from another export (#error). */
#define FIELDCAL_PAIR_ID @PAIR_ID@

/* ---- the blob ---- */
#define FIELDCAL_BLOB_MAGIC 0x4C434446u /* "FDCL", little-endian */
#define FIELDCAL_BLOB_VERSION @BLOB_VERSION@u
#define FIELDCAL_N_FLOATS @N_FLOATS@u
/* magic 4, version 2, float count 2, sensor id 4, flags 4, floats 4 each, CRC-32 4 */
#define FIELDCAL_BLOB_SIZE (16u + 4u * FIELDCAL_N_FLOATS + 4u)

/* status codes (every entry point that returns int; fieldcal_save returns the size on success) */
#define FIELDCAL_OK 0
#define FIELDCAL_ERR_SIZE (-1)
#define FIELDCAL_ERR_MAGIC (-2)
#define FIELDCAL_ERR_VERSION (-3)
#define FIELDCAL_ERR_CRC (-4)
#define FIELDCAL_ERR_SENSOR (-5)
#define FIELDCAL_ERR_VALUE (-6)   /* a value is not finite or not plausible (fieldcal_check) */
#define FIELDCAL_ERR_MISSING (-7) /* the calibration has no such sensor (or no monitor) */

/* flags: which parts the calibration has */
#define FIELDCAL_HAS_ACCEL 0x1u
#define FIELDCAL_HAS_MAG 0x2u
#define FIELDCAL_HAS_GYRO 0x4u
#define FIELDCAL_HAS_DECLINATION 0x8u
#define FIELDCAL_HAS_MONITOR 0x10u
@TEMPERATURE_FLAG@
#define FIELDCAL_KNOWN_FLAGS @KNOWN_FLAGS@ /* any other bit: FIELDCAL_ERR_VALUE */

/* What a calibration must be to load, to save and to be used (fieldcal_check; all floats
 * finite; "calibrated units" are the sensor's after M). Each sensor it has (its flag):
 *   - M = inv(gain) invertible: its largest |M_ij| within [FIELDCAL_MATRIX_MIN, _MAX] and
 *     |M|_F |inv(M)|_F <= FIELDCAL_CONDITION_MAX (a bound on the condition number), so the
 *     gain M^-1 is positive-definite in the sense M^T M > 0 (a mirrored axis is allowed);
 *   - |M b| <= FIELDCAL_BIAS_MAX per axis (the bias in calibrated units), temperature terms
 *     included at both ends of their span (T_min <= T_max, both within -273.15..1000 deg C).
 * At least one sensor; no unknown flag bit; the declination within [-180, 180] degrees.
 * With FIELDCAL_HAS_MONITOR (which needs the accelerometer and the magnetometer): gravity_norm
 * and field_norm within [FIELDCAL_NORM_MIN, _MAX]; the dip within [-90, 90] degrees; the
 * per-sample variances positive (at least FIELDCAL_VAR_MIN x F^2 for the norm, x 1 rad^2 for
 * the dip), the fixed ones >= 0, all at most F^2 (norm) and 1 rad^2 (dip); 0 < accel_norm_tol
 * <= gravity_norm; 0 < monitor_threshold <= FIELDCAL_THRESHOLD_MAX; hard_iron_cov symmetric
 * positive-definite (its correlation matrix's determinant >= FIELDCAL_CORRELATION_DET_MIN)
 * with each variance within [FIELDCAL_VAR_MIN F^2, F^2]; 0 <= hard_iron_q <= (0.1 F)^2. */
#define FIELDCAL_MATRIX_MIN 1e-12f
#define FIELDCAL_MATRIX_MAX 1e12f
#define FIELDCAL_CONDITION_MAX 1e4f
#define FIELDCAL_BIAS_MAX 1e6f
#define FIELDCAL_NORM_MIN 1e-9f
#define FIELDCAL_NORM_MAX 1e9f
#define FIELDCAL_VAR_MIN 1e-14f
#define FIELDCAL_THRESHOLD_MAX 1e6f
#define FIELDCAL_CORRELATION_DET_MIN 1e-6f
/* What a sample must be to be used (every other one is rejected and counted, never used):
 * finite; the update: ||m - beta| - F| <= FIELDCAL_MAG_GATE F and each innovation within
 * FIELDCAL_INNOVATION_GATE standard deviations; the monitor: |m| <= FIELDCAL_MONITOR_GATE F. */
#define FIELDCAL_MAG_GATE 0.5f
#define FIELDCAL_INNOVATION_GATE 5.0f
#define FIELDCAL_MONITOR_GATE 16.0f

typedef struct {
    uint32_t sensor_id; /* refuse a blob written for another sensor */
    uint32_t flags;     /* FIELDCAL_HAS_* */
    float accel_matrix[9], accel_bias[3]; /* row-major M = inv(gain); raw units */
    float mag_matrix[9], mag_bias[3];
    float gyro_matrix[9], gyro_bias[3];   /* gyroscope out in rad/s */
    float declination_deg;  /* true heading = magnetic heading + declination (east +) */
    float gravity_norm;     /* |a| at rest, calibrated accelerometer units */
    float field_norm;       /* |m| expected, calibrated magnetometer units */
    float dip_deg;          /* expected dip (inclination), degrees, positive down */
    float norm_var_sample;  /* variance of |m| from one sample's noise */
    float norm_var_fixed;   /* variance of |m| that averaging keeps (pose-level, calibration) */
    float dip_var_sample;   /* variance of the dip (rad^2) from one sample's noise */
    float dip_var_fixed;    /* variance of the dip (rad^2) that averaging keeps */
    float accel_norm_tol;   /* a sample is used when ||a| - gravity_norm| <= this */
    float monitor_threshold; /* alarm when the window's mean statistic exceeds this */
    float hard_iron_cov[9]; /* covariance of the magnetometer bias, body frame, units^2 */
    float hard_iron_q;      /* random walk of the hard iron per update, units^2 */
@TEMPERATURE_FIELDS@
} fieldcal_cal_t;

/* The calibration this file was generated from. */
extern const fieldcal_cal_t FIELDCAL_FACTORY;

/* ---- apply ---- */
/* out = M (raw - b). Returns FIELDCAL_OK, or FIELDCAL_ERR_VALUE for a non-finite raw value or
 * result (out is then NaN, which every other entry point rejects); the sensor functions also
 * FIELDCAL_ERR_MISSING when the calibration has no such sensor (out NaN). */
int fieldcal_apply(const float M[9], const float b[3], const float raw[3], float out[3]);
int fieldcal_accel(const fieldcal_cal_t *cal, const float raw[3], float out[3]);
int fieldcal_mag(const fieldcal_cal_t *cal, const float raw[3], float out[3]);
int fieldcal_gyro(const fieldcal_cal_t *cal, const float raw[3], float out[3]);
@TEMPERATURE_API@
@INTERFERENCE_API@
/* Tilt from level (degrees) of a body-frame specific force; roll and pitch (Z-Y-X, degrees)
 * when the pointers are not NULL. NaN (all three) for a zero or non-finite accel. */
float fieldcal_tilt(const float accel[3], float *roll_deg, float *pitch_deg);
/* Heading of the body x axis, degrees in [0, 360), from body-frame accelerometer and
 * magnetometer; true north when the calibration has a declination, magnetic north otherwise.
 * NaN for a zero or non-finite vector or a field along gravity (no horizontal part). */
float fieldcal_heading(const fieldcal_cal_t *cal, const float accel[3], const float mag[3]);

/* ---- keep ---- */
/* FIELDCAL_OK when the calibration is one fieldcal_load accepts (the rules above), else
 * FIELDCAL_ERR_VALUE: the one check fieldcal_save and fieldcal_load share. */
int fieldcal_check(const fieldcal_cal_t *cal);
/* Serialise to buf (at least FIELDCAL_BLOB_SIZE bytes); returns the bytes written, or
 * FIELDCAL_ERR_SIZE, or FIELDCAL_ERR_VALUE (fieldcal_check) writing nothing: a saved blob
 * always loads. Little-endian, CRC-32 (IEEE, as zlib's crc32) over all but the last 4. */
int fieldcal_save(const fieldcal_cal_t *cal, uint8_t *buf, size_t len);
/* Load a blob; refuses a wrong size, magic, version, CRC, sensor id or a value fieldcal_check
 * refuses (FIELDCAL_ERR_*), leaving *cal untouched. */
int fieldcal_load(fieldcal_cal_t *cal, const uint8_t *buf, size_t len, uint32_t sensor_id);
uint32_t fieldcal_crc32(const uint8_t *data, size_t len);

/* ---- check ---- */
#define FIELDCAL_MONITOR_BLOCK 16 /* samples averaged per block */
#ifndef FIELDCAL_MONITOR_WINDOW
#define FIELDCAL_MONITOR_WINDOW 8 /* blocks averaged per decision; monitor_threshold is
                                   * computed for 8 (another value changes the alarm rate) */
#endif
#define FIELDCAL_MONITOR_PENDING 0 /* sample taken, no decision yet */
#define FIELDCAL_MONITOR_OK 1      /* a block ended: the calibration holds */
#define FIELDCAL_MONITOR_ALARM 2   /* a block ended: it no longer holds */
#define FIELDCAL_MONITOR_MOVING 3  /* sample skipped: |a| is not g (the device accelerates) */
#define FIELDCAL_MONITOR_REJECTED 4 /* sample rejected: not finite, |m| beyond the gate, or the
                                     * calibration has no monitor (FIELDCAL_HAS_MONITOR) */

typedef struct {
    float sum_norm, sum_dip;          /* the current block's sums */
    uint16_t n;                       /* samples in the current block */
    uint8_t head, filled;             /* ring of the last blocks' statistics */
    float d2[FIELDCAL_MONITOR_WINDOW];
    float statistic;                  /* the window's mean of d2 (chi-square, 2 dof, each) */
    float norm, dip_deg;              /* the last block's mean |m| and dip */
    uint32_t blocks, alarms;
    uint32_t rejected;                /* samples rejected (FIELDCAL_MONITOR_REJECTED) */
} fieldcal_monitor_t;

void fieldcal_monitor_init(fieldcal_monitor_t *mon);
/* Feed one body-frame sample (fieldcal_accel / fieldcal_mag output, hard iron update applied). */
int fieldcal_monitor_update(fieldcal_monitor_t *mon, const fieldcal_cal_t *cal,
                            const float accel[3], const float mag[3]);

/* ---- update ---- */
typedef struct {
    float beta[3];      /* change of the hard iron, body frame, calibrated units */
    float P[9];         /* its covariance */
    float last_d[3], last_m[3]; /* directions at the last update (novelty gate) */
    uint32_t updates;
    uint32_t rejected;  /* samples rejected: not finite, beyond a gate (FIELDCAL_MAG_GATE, ...) */
    float field_norm;   /* F of the calibration it started from (bounds beta and P) */
} fieldcal_hardiron_t;

/* Start from the calibration: beta = 0, P = its hard-iron covariance. FIELDCAL_ERR_MISSING
 * (no monitor) or FIELDCAL_ERR_VALUE (fieldcal_check) leave P = 0: no sample is then used. */
int fieldcal_hardiron_init(fieldcal_hardiron_t *h, const fieldcal_cal_t *cal);
/* Allow a change of the hard iron of about std (calibrated units) per axis: P += std^2 I,
 * each variance at most F^2. Call it when the monitor alarms (a magnet was added, the hard
 * iron moved). FIELDCAL_ERR_VALUE (nothing changed) unless 0 <= std <= F, the field's norm. */
int fieldcal_hardiron_widen(fieldcal_hardiron_t *h, float std);
/* One body-frame sample (before fieldcal_hardiron_apply); returns 1 when it updated the
 * estimate, 0 when the sample was skipped (moving, or too close to the last one used) or
 * rejected (not finite, beyond a gate: counted in h->rejected). The estimate stays finite,
 * |beta| <= F per axis, P symmetric positive-definite. */
int fieldcal_hardiron_update(fieldcal_hardiron_t *h, const fieldcal_cal_t *cal,
                             const float accel[3], const float mag[3]);
/* mag -= beta: the body-frame field with the updated hard iron; FIELDCAL_ERR_VALUE (mag NaN)
 * for a non-finite mag. */
int fieldcal_hardiron_apply(const fieldcal_hardiron_t *h, float mag[3]);
/* Standard deviation of each component of beta. */
void fieldcal_hardiron_std(const fieldcal_hardiron_t *h, float std[3]);
/* Fold the update into the calibration (mag_bias += inv(M) beta, hard_iron_cov = P) so that
 * fieldcal_save keeps it; restarts h from the new calibration. FIELDCAL_ERR_VALUE when the
 * result would fail fieldcal_check: then neither *cal nor *h changes. */
int fieldcal_hardiron_fold(fieldcal_hardiron_t *h, fieldcal_cal_t *cal);

#endif /* FIELDCAL_CAL_H */
