/* fieldcal on a microcontroller: the library (see fieldcal_cal.h and docs/microcontroller.md).
 *
@PROVENANCE@
 */
#include "fieldcal_cal.h"

#include <math.h>

#if !defined(FIELDCAL_PAIR_ID) || FIELDCAL_PAIR_ID != @PAIR_ID@
#error "fieldcal_cal.h is not the one exported with this fieldcal_cal.c: export both again"
#endif
#if defined(__FAST_MATH__) || (defined(__FINITE_MATH_ONLY__) && __FINITE_MATH_ONLY__)
#error "fieldcal_cal.c tests for NaN and infinity: build it without -ffast-math"
#endif

#define FC_PI 3.14159265358979f
#define FC_DEG (180.0f / FC_PI)

/* ------------------------------------------------------------------ the factory calibration */
@FACTORY@

/* ------------------------------------------------------------------------------ apply */
static float fc_dot(const float a[3], const float b[3])
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

static float fc_norm(const float a[3])
{
    return sqrtf(fc_dot(a, a));
}

static int fc_finite(const float *v, unsigned n)
{
    unsigned i;
    for (i = 0; i < n; i++) {
        if (!isfinite(v[i])) {
            return 0;
        }
    }
    return 1;
}

static int fc_finite3(const float v[3])
{
    return v != NULL && fc_finite(v, 3u);
}

static void fc_nan3(float out[3])
{
    out[0] = out[1] = out[2] = NAN;
}

static float fc_max_abs(const float *v, unsigned n)
{
    float m = 0.0f;
    unsigned i;
    for (i = 0; i < n; i++) {
        m = fabsf(v[i]) > m ? fabsf(v[i]) : m;
    }
    return m;
}

/* out = M v (out must not be v) */
static void fc_mul(const float M[9], const float v[3], float out[3])
{
    int i;
    for (i = 0; i < 3; i++) {
        out[i] = M[3 * i] * v[0] + M[3 * i + 1] * v[1] + M[3 * i + 2] * v[2];
    }
}

/* v / |v|, scaled first so that no square overflows or underflows; 0 for a zero or
 * non-finite v */
static int fc_unit(const float v[3], float out[3])
{
    float m, n;
    int i;
    if (!fc_finite3(v) || !((m = fc_max_abs(v, 3u)) > 0.0f)) {
        return 0;
    }
    for (i = 0; i < 3; i++) {
        out[i] = v[i] / m;
    }
    n = fc_norm(out);
    for (i = 0; i < 3; i++) {
        out[i] /= n;
    }
    return 1;
}

/* inv(M) when M is invertible within the documented bounds (FIELDCAL_MATRIX_MIN/_MAX,
 * FIELDCAL_CONDITION_MAX), else 0; computed on M over its largest entry, so nothing overflows */
static int fc_inverse(const float M[9], float inv[9])
{
    float A[9], adj[9], m, det, fro = 0.0f, afro = 0.0f;
    int i;
    if (!fc_finite(M, 9u)) {
        return 0;
    }
    m = fc_max_abs(M, 9u);
    if (!(m >= FIELDCAL_MATRIX_MIN && m <= FIELDCAL_MATRIX_MAX)) {
        return 0;
    }
    for (i = 0; i < 9; i++) {
        A[i] = M[i] / m;
    }
    adj[0] = A[4] * A[8] - A[5] * A[7];
    adj[1] = A[2] * A[7] - A[1] * A[8];
    adj[2] = A[1] * A[5] - A[2] * A[4];
    adj[3] = A[5] * A[6] - A[3] * A[8];
    adj[4] = A[0] * A[8] - A[2] * A[6];
    adj[5] = A[2] * A[3] - A[0] * A[5];
    adj[6] = A[3] * A[7] - A[4] * A[6];
    adj[7] = A[1] * A[6] - A[0] * A[7];
    adj[8] = A[0] * A[4] - A[1] * A[3];
    det = A[0] * adj[0] + A[1] * adj[3] + A[2] * adj[6];
    for (i = 0; i < 9; i++) {
        fro += A[i] * A[i];
        afro += adj[i] * adj[i];
    }
    /* |A|_F |inv(A)|_F = |A|_F |adj(A)|_F / |det A|, at least the condition number */
    if (!(sqrtf(fro * afro) <= FIELDCAL_CONDITION_MAX * fabsf(det))) {
        return 0;
    }
    for (i = 0; i < 9; i++) {
        inv[i] = adj[i] / det / m;
    }
    return 1;
}

int fieldcal_apply(const float M[9], const float b[3], const float raw[3], float out[3])
{
    float d[3];
    int i;
    if (out == NULL) {
        return FIELDCAL_ERR_VALUE;
    }
    if (M == NULL || b == NULL || !fc_finite3(raw)) {
        fc_nan3(out);
        return FIELDCAL_ERR_VALUE;
    }
    for (i = 0; i < 3; i++) { /* raw may be out */
        d[i] = raw[i] - b[i];
    }
    fc_mul(M, d, out);
    if (!fc_finite3(out)) {
        fc_nan3(out);
        return FIELDCAL_ERR_VALUE;
    }
    return FIELDCAL_OK;
}

/* A sensor of the calibration (has: its flag is set), or FIELDCAL_ERR_MISSING. */
static int fc_sensor(int has, const float M[9], const float b[3], const float raw[3],
                     float out[3])
{
    if (out == NULL) {
        return FIELDCAL_ERR_VALUE;
    }
    if (!has) {
        fc_nan3(out);
        return FIELDCAL_ERR_MISSING;
    }
    return fieldcal_apply(M, b, raw, out);
}

int fieldcal_accel(const fieldcal_cal_t *cal, const float raw[3], float out[3])
{
    if (cal == NULL) {
        return fc_sensor(0, NULL, NULL, raw, out);
    }
    return fc_sensor((cal->flags & FIELDCAL_HAS_ACCEL) != 0u, cal->accel_matrix, cal->accel_bias,
                     raw, out);
}

int fieldcal_mag(const fieldcal_cal_t *cal, const float raw[3], float out[3])
{
    if (cal == NULL) {
        return fc_sensor(0, NULL, NULL, raw, out);
    }
    return fc_sensor((cal->flags & FIELDCAL_HAS_MAG) != 0u, cal->mag_matrix, cal->mag_bias, raw,
                     out);
}

int fieldcal_gyro(const fieldcal_cal_t *cal, const float raw[3], float out[3])
{
    if (cal == NULL) {
        return fc_sensor(0, NULL, NULL, raw, out);
    }
    return fc_sensor((cal->flags & FIELDCAL_HAS_GYRO) != 0u, cal->gyro_matrix, cal->gyro_bias,
                     raw, out);
}
@TEMPERATURE_CODE@
@INTERFERENCE_CODE@

float fieldcal_tilt(const float accel[3], float *roll_deg, float *pitch_deg)
{
    /* down, in the body frame: the specific force at rest points up */
    float d[3], c;
    const int ok = fc_unit(accel, d);
    int i;
    for (i = 0; ok && i < 3; i++) {
        d[i] = -d[i];
    }
    if (roll_deg != NULL) {
        *roll_deg = ok ? atan2f(d[1], d[2]) * FC_DEG : NAN;
    }
    if (pitch_deg != NULL) {
        *pitch_deg = ok ? atan2f(-d[0], sqrtf(d[1] * d[1] + d[2] * d[2])) * FC_DEG : NAN;
    }
    if (!ok) {
        return NAN;
    }
    c = d[2] > 1.0f ? 1.0f : (d[2] < -1.0f ? -1.0f : d[2]);
    return acosf(c) * FC_DEG;
}

float fieldcal_heading(const fieldcal_cal_t *cal, const float accel[3], const float mag[3])
{
    /* with unit vectors d (down) and m: north (the field's horizontal part) n = m - d (d.m),
     * east e = d x n; the body x axis has north component n_x and east component e_x */
    float d[3], m[3], n[3], dm, east_x, h;
    int i;
    if (cal == NULL || !fc_unit(accel, d) || !fc_unit(mag, m)) {
        return NAN;
    }
    for (i = 0; i < 3; i++) {
        d[i] = -d[i];
    }
    dm = fc_dot(d, m);
    for (i = 0; i < 3; i++) {
        n[i] = m[i] - d[i] * dm;
    }
    if (!(fc_norm(n) > 1e-4f)) { /* the field along gravity: no north */
        return NAN;
    }
    east_x = d[1] * n[2] - d[2] * n[1];
    h = atan2f(east_x, n[0]) * FC_DEG;
    if (cal->flags & FIELDCAL_HAS_DECLINATION) {
        if (!(fabsf(cal->declination_deg) <= 180.0f)) {
            return NAN;
        }
        h += cal->declination_deg;
    }
    h = fmodf(h, 360.0f);
    if (h < 0.0f) {
        h += 360.0f;
    }
    return h >= 360.0f ? 0.0f : h;
}

/* ------------------------------------------------------------------------------- keep */
uint32_t fieldcal_crc32(const uint8_t *data, size_t len)
{
    uint32_t crc = 0xFFFFFFFFu;
    size_t i;
    int k;
    if (data == NULL) {
        return 0u;
    }
    for (i = 0; i < len; i++) {
        crc ^= data[i];
        for (k = 0; k < 8; k++) {
            crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
        }
    }
    return crc ^ 0xFFFFFFFFu;
}

static void fc_put32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)(v & 0xFFu);
    p[1] = (uint8_t)((v >> 8) & 0xFFu);
    p[2] = (uint8_t)((v >> 16) & 0xFFu);
    p[3] = (uint8_t)((v >> 24) & 0xFFu);
}

static uint32_t fc_get32(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) |
           ((uint32_t)p[3] << 24);
}

/* Every float of the calibration, in blob order. */
static void fc_fields(fieldcal_cal_t *c, float *f[FIELDCAL_N_FLOATS])
{
    unsigned n = 0, i;
    for (i = 0; i < 9; i++) f[n++] = &c->accel_matrix[i];
    for (i = 0; i < 3; i++) f[n++] = &c->accel_bias[i];
    for (i = 0; i < 9; i++) f[n++] = &c->mag_matrix[i];
    for (i = 0; i < 3; i++) f[n++] = &c->mag_bias[i];
    for (i = 0; i < 9; i++) f[n++] = &c->gyro_matrix[i];
    for (i = 0; i < 3; i++) f[n++] = &c->gyro_bias[i];
    f[n++] = &c->declination_deg;
    f[n++] = &c->gravity_norm;
    f[n++] = &c->field_norm;
    f[n++] = &c->dip_deg;
    f[n++] = &c->norm_var_sample;
    f[n++] = &c->norm_var_fixed;
    f[n++] = &c->dip_var_sample;
    f[n++] = &c->dip_var_fixed;
    f[n++] = &c->accel_norm_tol;
    f[n++] = &c->monitor_threshold;
    for (i = 0; i < 9; i++) f[n++] = &c->hard_iron_cov[i];
    f[n++] = &c->hard_iron_q;
@TEMPERATURE_BLOB@
}

/* A covariance: symmetric, each variance within [lo, hi], positive-definite (its correlation
 * matrix's leading minors positive, its determinant at least FIELDCAL_CORRELATION_DET_MIN). */
static int fc_cov_ok(const float P[9], float lo, float hi)
{
    float s[3], r01, r02, r12;
    int i;
    for (i = 0; i < 3; i++) {
        if (!(P[4 * i] >= lo && P[4 * i] <= hi)) {
            return 0;
        }
        s[i] = sqrtf(P[4 * i]);
    }
    if (!(P[1] == P[3] && P[2] == P[6] && P[5] == P[7])) {
        return 0;
    }
    r01 = P[1] / (s[0] * s[1]);
    r02 = P[2] / (s[0] * s[2]);
    r12 = P[5] / (s[1] * s[2]);
    return r01 * r01 < 1.0f && r02 * r02 < 1.0f && r12 * r12 < 1.0f &&
           1.0f + 2.0f * r01 * r02 * r12 - r01 * r01 - r02 * r02 - r12 * r12 >=
               FIELDCAL_CORRELATION_DET_MIN;
}

/* The monitor's and the update's numbers (FIELDCAL_HAS_MONITOR and the bounds in the header). */
static int fc_monitor_ok(const fieldcal_cal_t *c)
{
    const float F = c->field_norm, g = c->gravity_norm, F2 = F * F;
    if (!(c->flags & FIELDCAL_HAS_MONITOR)) {
        return 0;
    }
    if (!(g >= FIELDCAL_NORM_MIN && g <= FIELDCAL_NORM_MAX && F >= FIELDCAL_NORM_MIN &&
          F <= FIELDCAL_NORM_MAX && fabsf(c->dip_deg) <= 90.0f)) {
        return 0;
    }
    if (!(c->norm_var_sample >= FIELDCAL_VAR_MIN * F2 && c->norm_var_sample <= F2 &&
          c->norm_var_fixed >= 0.0f && c->norm_var_fixed <= F2 &&
          c->dip_var_sample >= FIELDCAL_VAR_MIN && c->dip_var_sample <= 1.0f &&
          c->dip_var_fixed >= 0.0f && c->dip_var_fixed <= 1.0f)) {
        return 0;
    }
    if (!(c->accel_norm_tol > 0.0f && c->accel_norm_tol <= g && c->monitor_threshold > 0.0f &&
          c->monitor_threshold <= FIELDCAL_THRESHOLD_MAX && c->hard_iron_q >= 0.0f &&
          c->hard_iron_q <= 0.01f * F2)) {
        return 0;
    }
    return fc_cov_ok(c->hard_iron_cov, FIELDCAL_VAR_MIN * F2, F2);
}

/* A sensor's M invertible within bounds and its bias, in calibrated units, within bounds. */
static int fc_sensor_ok(const float M[9], const float b[3])
{
    float inv[9], mb[3];
    int i;
    if (!fc_inverse(M, inv) || !fc_finite3(b)) {
        return 0;
    }
    fc_mul(M, b, mb);
    for (i = 0; i < 3; i++) {
        if (!(fabsf(mb[i]) <= FIELDCAL_BIAS_MAX)) {
            return 0;
        }
    }
    return 1;
}

int fieldcal_check(const fieldcal_cal_t *cal)
{
    const uint32_t sensors = FIELDCAL_HAS_ACCEL | FIELDCAL_HAS_MAG | FIELDCAL_HAS_GYRO;
    fieldcal_cal_t copy;
    float *f[FIELDCAL_N_FLOATS];
    uint32_t flags;
    unsigned i;
    if (cal == NULL) {
        return FIELDCAL_ERR_VALUE;
    }
    copy = *cal;
    flags = copy.flags;
    fc_fields(&copy, f);
    for (i = 0; i < FIELDCAL_N_FLOATS; i++) {
        if (!isfinite(*f[i])) {
            return FIELDCAL_ERR_VALUE;
        }
    }
    if ((flags & ~FIELDCAL_KNOWN_FLAGS) != 0u || (flags & sensors) == 0u) {
        return FIELDCAL_ERR_VALUE;
    }
    if (((flags & FIELDCAL_HAS_ACCEL) && !fc_sensor_ok(cal->accel_matrix, cal->accel_bias)) ||
        ((flags & FIELDCAL_HAS_MAG) && !fc_sensor_ok(cal->mag_matrix, cal->mag_bias)) ||
        ((flags & FIELDCAL_HAS_GYRO) && !fc_sensor_ok(cal->gyro_matrix, cal->gyro_bias))) {
        return FIELDCAL_ERR_VALUE;
    }
@TEMPERATURE_CHECK@
    if ((flags & FIELDCAL_HAS_DECLINATION) && !(fabsf(cal->declination_deg) <= 180.0f)) {
        return FIELDCAL_ERR_VALUE;
    }
    if ((flags & FIELDCAL_HAS_MONITOR) &&
        (!(flags & FIELDCAL_HAS_ACCEL) || !(flags & FIELDCAL_HAS_MAG) || !fc_monitor_ok(cal))) {
        return FIELDCAL_ERR_VALUE;
    }
    return FIELDCAL_OK;
}

int fieldcal_save(const fieldcal_cal_t *cal, uint8_t *buf, size_t len)
{
    fieldcal_cal_t copy;
    float *f[FIELDCAL_N_FLOATS];
    uint32_t bits;
    unsigned i;
    if (buf == NULL || len < FIELDCAL_BLOB_SIZE) {
        return FIELDCAL_ERR_SIZE;
    }
    if (fieldcal_check(cal) != FIELDCAL_OK) { /* what fieldcal_load would refuse: not written */
        return FIELDCAL_ERR_VALUE;
    }
    copy = *cal;
    fc_fields(&copy, f);
    fc_put32(buf, FIELDCAL_BLOB_MAGIC);
    buf[4] = (uint8_t)(FIELDCAL_BLOB_VERSION & 0xFFu);
    buf[5] = (uint8_t)(FIELDCAL_BLOB_VERSION >> 8);
    buf[6] = (uint8_t)(FIELDCAL_N_FLOATS & 0xFFu);
    buf[7] = (uint8_t)(FIELDCAL_N_FLOATS >> 8);
    fc_put32(buf + 8, cal->sensor_id);
    fc_put32(buf + 12, cal->flags);
    for (i = 0; i < FIELDCAL_N_FLOATS; i++) {
        memcpy(&bits, f[i], sizeof bits);
        fc_put32(buf + 16 + 4 * i, bits);
    }
    fc_put32(buf + FIELDCAL_BLOB_SIZE - 4, fieldcal_crc32(buf, FIELDCAL_BLOB_SIZE - 4));
    return (int)FIELDCAL_BLOB_SIZE;
}

int fieldcal_load(fieldcal_cal_t *cal, const uint8_t *buf, size_t len, uint32_t sensor_id)
{
    fieldcal_cal_t out;
    float *f[FIELDCAL_N_FLOATS];
    uint32_t bits;
    unsigned i;
    if (cal == NULL || buf == NULL || len != FIELDCAL_BLOB_SIZE) {
        return FIELDCAL_ERR_SIZE;
    }
    if (fc_get32(buf) != FIELDCAL_BLOB_MAGIC) {
        return FIELDCAL_ERR_MAGIC;
    }
    if (((uint32_t)buf[4] | ((uint32_t)buf[5] << 8)) != FIELDCAL_BLOB_VERSION ||
        ((uint32_t)buf[6] | ((uint32_t)buf[7] << 8)) != FIELDCAL_N_FLOATS) {
        return FIELDCAL_ERR_VERSION;
    }
    if (fc_get32(buf + FIELDCAL_BLOB_SIZE - 4) != fieldcal_crc32(buf, FIELDCAL_BLOB_SIZE - 4)) {
        return FIELDCAL_ERR_CRC;
    }
    if (fc_get32(buf + 8) != sensor_id) {
        return FIELDCAL_ERR_SENSOR;
    }
    memset(&out, 0, sizeof out);
    out.sensor_id = sensor_id;
    out.flags = fc_get32(buf + 12);
    fc_fields(&out, f);
    for (i = 0; i < FIELDCAL_N_FLOATS; i++) {
        bits = fc_get32(buf + 16 + 4 * i);
        memcpy(f[i], &bits, sizeof bits);
    }
    if (fieldcal_check(&out) != FIELDCAL_OK) {
        return FIELDCAL_ERR_VALUE;
    }
    *cal = out;
    return FIELDCAL_OK;
}

/* ------------------------------------------------------------------------------ check */
/* |m| and the dip (rad) of one finite body-frame sample; 0 when |a| is not g (the device
 * moves). */
static int fc_norm_dip(const fieldcal_cal_t *cal, const float accel[3], const float mag[3],
                       float *norm, float *dip)
{
    const float an = fc_norm(accel);
    float ua[3], um[3], s;
    *norm = fc_norm(mag);
    if (!(fabsf(an - cal->gravity_norm) <= cal->accel_norm_tol) || !fc_unit(accel, ua) ||
        !fc_unit(mag, um)) {
        return 0;
    }
    s = -fc_dot(ua, um); /* down . field direction */
    s = s > 1.0f ? 1.0f : (s < -1.0f ? -1.0f : s);
    *dip = asinf(s);
    return 1;
}

void fieldcal_monitor_init(fieldcal_monitor_t *mon)
{
    if (mon != NULL) {
        memset(mon, 0, sizeof *mon);
    }
}

int fieldcal_monitor_update(fieldcal_monitor_t *mon, const fieldcal_cal_t *cal,
                            const float accel[3], const float mag[3])
{
    float norm, dip, zn, zd, sum, d2;
    unsigned i;
    if (mon == NULL) {
        return FIELDCAL_MONITOR_REJECTED;
    }
    if (mon->n >= FIELDCAL_MONITOR_BLOCK || mon->head >= FIELDCAL_MONITOR_WINDOW ||
        mon->filled > FIELDCAL_MONITOR_WINDOW) {
        fieldcal_monitor_init(mon); /* not a state the monitor makes: start again */
    }
    if (cal == NULL || !fc_monitor_ok(cal) || !fc_finite3(accel) || !fc_finite3(mag) ||
        !(fc_norm(mag) <= FIELDCAL_MONITOR_GATE * cal->field_norm)) {
        mon->rejected++;
        return FIELDCAL_MONITOR_REJECTED;
    }
    if (!fc_norm_dip(cal, accel, mag, &norm, &dip)) {
        return FIELDCAL_MONITOR_MOVING;
    }
    mon->sum_norm += norm;
    mon->sum_dip += dip;
    if (++mon->n < FIELDCAL_MONITOR_BLOCK) {
        return FIELDCAL_MONITOR_PENDING;
    }
    /* the block's means against their expected values: d2 ~ chi-square with 2 dof */
    mon->norm = mon->sum_norm / (float)mon->n;
    mon->dip_deg = mon->sum_dip / (float)mon->n * FC_DEG;
    zn = (mon->norm - cal->field_norm) /
         sqrtf(cal->norm_var_fixed + cal->norm_var_sample / (float)mon->n);
    zd = (mon->dip_deg - cal->dip_deg) / FC_DEG /
         sqrtf(cal->dip_var_fixed + cal->dip_var_sample / (float)mon->n);
    d2 = zn * zn + zd * zd;
    mon->d2[mon->head] = d2 <= 1e30f ? d2 : 1e30f; /* the window's mean stays finite */
    mon->head = (uint8_t)((mon->head + 1u) % FIELDCAL_MONITOR_WINDOW);
    if (mon->filled < FIELDCAL_MONITOR_WINDOW) {
        mon->filled++;
    }
    mon->sum_norm = mon->sum_dip = 0.0f;
    mon->n = 0;
    mon->blocks++;
    sum = 0.0f;
    for (i = 0; i < mon->filled; i++) {
        sum += mon->d2[i];
    }
    mon->statistic = sum / (float)mon->filled;
    if (mon->statistic > cal->monitor_threshold) {
        mon->alarms++;
        return FIELDCAL_MONITOR_ALARM;
    }
    return FIELDCAL_MONITOR_OK;
}

/* ----------------------------------------------------------------------------- update */
/* An estimator fieldcal_hardiron_init made: beta finite within F per axis, P a covariance. */
static int fc_hardiron_ok(const fieldcal_hardiron_t *h)
{
    const float F = h->field_norm;
    return F >= FIELDCAL_NORM_MIN && F <= FIELDCAL_NORM_MAX && fc_finite3(h->beta) &&
           fc_max_abs(h->beta, 3u) <= F && fc_cov_ok(h->P, FIELDCAL_VAR_MIN * F * F, F * F);
}

/* P symmetric, each variance within [lo, hi], positive-definite: float rounding in an update
 * can break each, and fieldcal_check would then refuse the folded calibration. */
static void fc_repair_cov(float P[9], float lo, float hi)
{
    int i, j;
    for (i = 0; i < 3; i++) {
        for (j = i + 1; j < 3; j++) {
            const float m = 0.5f * (P[3 * i + j] + P[3 * j + i]);
            P[3 * i + j] = P[3 * j + i] = m;
        }
        P[4 * i] = P[4 * i] >= lo ? (P[4 * i] <= hi ? P[4 * i] : hi) : lo;
    }
    if (!fc_cov_ok(P, lo, hi)) { /* keep the variances, drop the correlations */
        P[1] = P[2] = P[3] = P[5] = P[6] = P[7] = 0.0f;
    }
}

int fieldcal_hardiron_init(fieldcal_hardiron_t *h, const fieldcal_cal_t *cal)
{
    if (h == NULL) {
        return FIELDCAL_ERR_VALUE;
    }
    memset(h, 0, sizeof *h);
    if (cal == NULL || !(cal->flags & FIELDCAL_HAS_MONITOR)) {
        return FIELDCAL_ERR_MISSING;
    }
    if (fieldcal_check(cal) != FIELDCAL_OK) {
        return FIELDCAL_ERR_VALUE;
    }
    memcpy(h->P, cal->hard_iron_cov, sizeof h->P);
    h->field_norm = cal->field_norm;
    return FIELDCAL_OK;
}

int fieldcal_hardiron_widen(fieldcal_hardiron_t *h, float std)
{
    float F;
    int i;
    if (h == NULL || !fc_hardiron_ok(h) || !(std >= 0.0f && std <= h->field_norm)) {
        return FIELDCAL_ERR_VALUE;
    }
    F = h->field_norm;
    for (i = 0; i < 9; i += 4) {
        h->P[i] += std * std;
    }
    fc_repair_cov(h->P, FIELDCAL_VAR_MIN * F * F, F * F);
    return FIELDCAL_OK;
}

/* One scalar measurement y = H beta + noise (variance r): the Kalman update of beta, P; 0 (and
 * nothing done) when the innovation is beyond FIELDCAL_INNOVATION_GATE standard deviations. */
static int fc_kalman(fieldcal_hardiron_t *h, const float H[3], float innovation, float r)
{
    const float gate = FIELDCAL_INNOVATION_GATE * FIELDCAL_INNOVATION_GATE;
    float PH[3], s, k[3];
    int i, j;
    for (i = 0; i < 3; i++) {
        PH[i] = h->P[3 * i] * H[0] + h->P[3 * i + 1] * H[1] + h->P[3 * i + 2] * H[2];
    }
    s = fc_dot(H, PH) + r;
    if (!(s > 0.0f) || !(innovation * innovation <= gate * s)) {
        return 0;
    }
    for (i = 0; i < 3; i++) {
        k[i] = PH[i] / s;
        h->beta[i] += k[i] * innovation;
    }
    for (i = 0; i < 3; i++) {
        for (j = 0; j < 3; j++) {
            h->P[3 * i + j] -= k[i] * PH[j];
        }
    }
    return 1;
}

int fieldcal_hardiron_update(fieldcal_hardiron_t *h, const fieldcal_cal_t *cal,
                             const float accel[3], const float mag[3])
{
    fieldcal_hardiron_t next;
    float u[3], d[3], H[3], un, F, cd, sd, norm, dip;
    int i;
    if (h == NULL) {
        return 0;
    }
    if (cal == NULL || !fc_monitor_ok(cal) || !fc_hardiron_ok(h) || !fc_finite3(accel) ||
        !fc_finite3(mag)) {
        h->rejected++;
        return 0;
    }
    /* the measured field with the current estimate: u = m - beta */
    F = cal->field_norm;
    for (i = 0; i < 3; i++) {
        u[i] = mag[i] - h->beta[i];
    }
    un = fc_norm(u);
    if (!(fabsf(un - F) <= FIELDCAL_MAG_GATE * F)) { /* a glitch, or a magnet: not the field */
        h->rejected++;
        return 0;
    }
    if (!fc_norm_dip(cal, accel, u, &norm, &dip) || !fc_unit(accel, d)) {
        return 0;
    }
    for (i = 0; i < 3; i++) {
        d[i] = -d[i];
    }
    /* novelty: skip a sample whose directions are within 5 degrees of the last one used, so
     * the pose-level error (the same in one orientation) is not counted again and again */
    if (h->updates > 0 && fc_dot(d, h->last_d) > 0.9962f &&
        fc_dot(u, h->last_m) / un > 0.9962f) {
        return 0;
    }
    next = *h;
    cd = cosf(cal->dip_deg / FC_DEG);
    sd = sinf(cal->dip_deg / FC_DEG);
    for (i = 0; i < 9; i += 4) {
        next.P[i] += cal->hard_iron_q;
    }
    /* dip, linear: d . (m - beta) = F sin(dip), so d . m - F sin(dip) = d . beta + noise;
     * norm, linearised at beta: |m - beta| = F, H = -(m - beta)/|m - beta| */
    for (i = 0; i < 3; i++) {
        H[i] = -u[i] / un;
    }
    if (!fc_kalman(&next, d, fc_dot(d, mag) - F * sd - fc_dot(d, h->beta),
                   F * F * cd * cd * (cal->dip_var_sample + cal->dip_var_fixed)) ||
        !fc_kalman(&next, H, F - un, cal->norm_var_sample + cal->norm_var_fixed)) {
        h->rejected++; /* an innovation beyond the gate: an outlier, not an update */
        return 0;
    }
    fc_repair_cov(next.P, FIELDCAL_VAR_MIN * next.field_norm * next.field_norm,
                  next.field_norm * next.field_norm);
    if (!fc_finite3(next.beta) || !(fc_max_abs(next.beta, 3u) <= next.field_norm)) {
        h->rejected++;
        return 0;
    }
    for (i = 0; i < 3; i++) {
        next.last_d[i] = d[i];
        next.last_m[i] = u[i] / un;
    }
    next.updates++;
    *h = next;
    return 1;
}

int fieldcal_hardiron_apply(const fieldcal_hardiron_t *h, float mag[3])
{
    int i;
    if (mag == NULL) {
        return FIELDCAL_ERR_VALUE;
    }
    if (h == NULL || !fc_finite3(h->beta) || !fc_finite3(mag)) {
        fc_nan3(mag);
        return FIELDCAL_ERR_VALUE;
    }
    for (i = 0; i < 3; i++) {
        mag[i] -= h->beta[i];
    }
    if (!fc_finite3(mag)) {
        fc_nan3(mag);
        return FIELDCAL_ERR_VALUE;
    }
    return FIELDCAL_OK;
}

void fieldcal_hardiron_std(const fieldcal_hardiron_t *h, float std[3])
{
    int i;
    if (h == NULL || std == NULL) {
        return;
    }
    for (i = 0; i < 3; i++) {
        std[i] = sqrtf(h->P[4 * i] > 0.0f ? h->P[4 * i] : 0.0f);
    }
}

int fieldcal_hardiron_fold(fieldcal_hardiron_t *h, fieldcal_cal_t *cal)
{
    /* m = M (raw - b) - beta = M (raw - b - inv(M) beta): the new bias is b + inv(M) beta */
    fieldcal_cal_t next;
    float inv[9], shift[3];
    int i;
    if (h == NULL || cal == NULL || !fc_hardiron_ok(h) || !fc_inverse(cal->mag_matrix, inv)) {
        return FIELDCAL_ERR_VALUE;
    }
    next = *cal;
    fc_mul(inv, h->beta, shift);
    for (i = 0; i < 3; i++) {
        next.mag_bias[i] += shift[i];
    }
    memcpy(next.hard_iron_cov, h->P, sizeof h->P);
    if (fieldcal_check(&next) != FIELDCAL_OK) {
        return FIELDCAL_ERR_VALUE;
    }
    *cal = next;
    return fieldcal_hardiron_init(h, cal);
}
