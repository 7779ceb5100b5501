/* fieldcal on a microcontroller: the library (see fieldcal_cal.h and docs/microcontroller.md).
 *
@PROVENANCE@
 */
#include "fieldcal_cal.h"

#include <math.h>

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

void fieldcal_apply(const float M[9], const float b[3], const float raw[3], float out[3])
{
    const float d[3] = {raw[0] - b[0], raw[1] - b[1], raw[2] - b[2]};
    int i;
    for (i = 0; i < 3; i++) {
        out[i] = M[3 * i] * d[0] + M[3 * i + 1] * d[1] + M[3 * i + 2] * d[2];
    }
}

void fieldcal_accel(const fieldcal_cal_t *cal, const float raw[3], float out[3])
{
    fieldcal_apply(cal->accel_matrix, cal->accel_bias, raw, out);
}

void fieldcal_mag(const fieldcal_cal_t *cal, const float raw[3], float out[3])
{
    fieldcal_apply(cal->mag_matrix, cal->mag_bias, raw, out);
}

void fieldcal_gyro(const fieldcal_cal_t *cal, const float raw[3], float out[3])
{
    fieldcal_apply(cal->gyro_matrix, cal->gyro_bias, raw, out);
}
@TEMPERATURE_CODE@
@INTERFERENCE_CODE@

float fieldcal_tilt(const float accel[3], float *roll_deg, float *pitch_deg)
{
    /* down, in the body frame: the specific force at rest points up */
    const float d[3] = {-accel[0], -accel[1], -accel[2]};
    const float n = fc_norm(d);
    float c;
    if (roll_deg != NULL) {
        *roll_deg = atan2f(d[1], d[2]) * FC_DEG;
    }
    if (pitch_deg != NULL) {
        *pitch_deg = atan2f(-d[0], sqrtf(d[1] * d[1] + d[2] * d[2])) * FC_DEG;
    }
    if (!(n > 0.0f)) {
        return 0.0f;
    }
    c = d[2] / n;
    c = c > 1.0f ? 1.0f : (c < -1.0f ? -1.0f : c);
    return acosf(c) * FC_DEG;
}

float fieldcal_heading(const fieldcal_cal_t *cal, const float accel[3], const float mag[3])
{
    /* north (horizontal part of the field) n = m |d|^2 - d (d.m), east e = d x n; the body x
     * axis has north component n_x / |n| and east component e_x / (|d| |n|) */
    const float d[3] = {-accel[0], -accel[1], -accel[2]};
    const float dd = fc_dot(d, d);
    const float dm = fc_dot(d, mag);
    const float dn = sqrtf(dd);
    float n[3], east_x, h;
    int i;
    for (i = 0; i < 3; i++) {
        n[i] = mag[i] * dd - d[i] * dm;
    }
    east_x = d[1] * n[2] - d[2] * n[1];
    h = atan2f(east_x, dn * n[0]) * FC_DEG;
    if (cal->flags & FIELDCAL_HAS_DECLINATION) {
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

int fieldcal_save(const fieldcal_cal_t *cal, uint8_t *buf, size_t len)
{
    fieldcal_cal_t copy = *cal;
    float *f[FIELDCAL_N_FLOATS];
    uint32_t bits;
    unsigned i;
    if (buf == NULL || len < FIELDCAL_BLOB_SIZE) {
        return FIELDCAL_ERR_SIZE;
    }
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
    if (buf == NULL || len != FIELDCAL_BLOB_SIZE) {
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
        if (!isfinite(*f[i])) {
            return FIELDCAL_ERR_VALUE;
        }
    }
    *cal = out;
    return FIELDCAL_OK;
}

/* ------------------------------------------------------------------------------ check */
/* |m| and the dip (rad) of one body-frame sample; 0 when |a| is not g (the device moves). */
static int fc_norm_dip(const fieldcal_cal_t *cal, const float accel[3], const float mag[3],
                       float *norm, float *dip)
{
    const float an = fc_norm(accel);
    float s;
    *norm = fc_norm(mag);
    if (!(fabsf(an - cal->gravity_norm) <= cal->accel_norm_tol) || !(*norm > 0.0f)) {
        return 0;
    }
    s = -fc_dot(accel, mag) / (an * *norm); /* down . field direction */
    s = s > 1.0f ? 1.0f : (s < -1.0f ? -1.0f : s);
    *dip = asinf(s);
    return 1;
}

void fieldcal_monitor_init(fieldcal_monitor_t *mon)
{
    memset(mon, 0, sizeof *mon);
}

int fieldcal_monitor_update(fieldcal_monitor_t *mon, const fieldcal_cal_t *cal,
                            const float accel[3], const float mag[3])
{
    float norm, dip, zn, zd, sum;
    unsigned i;
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
    mon->d2[mon->head] = zn * zn + zd * zd;
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
void fieldcal_hardiron_init(fieldcal_hardiron_t *h, const fieldcal_cal_t *cal)
{
    memset(h, 0, sizeof *h);
    memcpy(h->P, cal->hard_iron_cov, sizeof h->P);
}

void fieldcal_hardiron_widen(fieldcal_hardiron_t *h, float std)
{
    int i;
    for (i = 0; i < 9; i += 4) {
        h->P[i] += std * std;
    }
}

/* One scalar measurement y = H beta + noise (variance r): the Kalman update of beta, P. */
static void fc_kalman(fieldcal_hardiron_t *h, const float H[3], float innovation, float r)
{
    float PH[3], s, k[3];
    int i, j;
    for (i = 0; i < 3; i++) {
        PH[i] = h->P[3 * i] * H[0] + h->P[3 * i + 1] * H[1] + h->P[3 * i + 2] * H[2];
    }
    s = fc_dot(H, PH) + r;
    if (!(s > 0.0f)) {
        return;
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
    for (i = 0; i < 3; i++) { /* keep P symmetric */
        for (j = i + 1; j < 3; j++) {
            const float m = 0.5f * (h->P[3 * i + j] + h->P[3 * j + i]);
            h->P[3 * i + j] = h->P[3 * j + i] = m;
        }
    }
}

int fieldcal_hardiron_update(fieldcal_hardiron_t *h, const fieldcal_cal_t *cal,
                             const float accel[3], const float mag[3])
{
    /* the measured field with the current estimate: u = m - beta */
    const float u[3] = {mag[0] - h->beta[0], mag[1] - h->beta[1], mag[2] - h->beta[2]};
    const float an = fc_norm(accel), un = fc_norm(u);
    const float cd = cosf(cal->dip_deg / FC_DEG), sd = sinf(cal->dip_deg / FC_DEG);
    float d[3], H[3], norm, dip;
    int i;
    if (!fc_norm_dip(cal, accel, u, &norm, &dip) || !(un > 0.0f)) {
        return 0;
    }
    for (i = 0; i < 3; i++) {
        d[i] = -accel[i] / an;
    }
    /* novelty: skip a sample whose directions are within 5 degrees of the last one used, so
     * the pose-level error (the same in one orientation) is not counted again and again */
    if (h->updates > 0 && fc_dot(d, h->last_d) > 0.9962f &&
        fc_dot(u, h->last_m) / un > 0.9962f) {
        return 0;
    }
    for (i = 0; i < 9; i += 4) {
        h->P[i] += cal->hard_iron_q;
    }
    /* dip, linear: d . (m - beta) = F sin(dip), so d . m - F sin(dip) = d . beta + noise */
    fc_kalman(h, d, fc_dot(d, mag) - cal->field_norm * sd - fc_dot(d, h->beta),
              cal->field_norm * cal->field_norm * cd * cd *
                  (cal->dip_var_sample + cal->dip_var_fixed));
    /* norm, linearised at beta: |m - beta| = F, H = -(m - beta)/|m - beta| */
    for (i = 0; i < 3; i++) {
        H[i] = -u[i] / un;
    }
    fc_kalman(h, H, cal->field_norm - un, cal->norm_var_sample + cal->norm_var_fixed);
    for (i = 0; i < 3; i++) {
        h->last_d[i] = d[i];
        h->last_m[i] = u[i] / un;
    }
    h->updates++;
    return 1;
}

void fieldcal_hardiron_apply(const fieldcal_hardiron_t *h, float mag[3])
{
    mag[0] -= h->beta[0];
    mag[1] -= h->beta[1];
    mag[2] -= h->beta[2];
}

void fieldcal_hardiron_std(const fieldcal_hardiron_t *h, float std[3])
{
    int i;
    for (i = 0; i < 3; i++) {
        std[i] = sqrtf(h->P[4 * i] > 0.0f ? h->P[4 * i] : 0.0f);
    }
}

void fieldcal_hardiron_fold(fieldcal_hardiron_t *h, fieldcal_cal_t *cal)
{
    /* m = M (raw - b) - beta = M (raw - b - inv(M) beta): the new bias is b + inv(M) beta */
    const float *M = cal->mag_matrix;
    const float det = M[0] * (M[4] * M[8] - M[5] * M[7]) - M[1] * (M[3] * M[8] - M[5] * M[6]) +
                      M[2] * (M[3] * M[7] - M[4] * M[6]);
    float inv[9], shift[3];
    int i;
    if (!(fabsf(det) > 0.0f)) {
        return;
    }
    inv[0] = (M[4] * M[8] - M[5] * M[7]) / det;
    inv[1] = (M[2] * M[7] - M[1] * M[8]) / det;
    inv[2] = (M[1] * M[5] - M[2] * M[4]) / det;
    inv[3] = (M[5] * M[6] - M[3] * M[8]) / det;
    inv[4] = (M[0] * M[8] - M[2] * M[6]) / det;
    inv[5] = (M[2] * M[3] - M[0] * M[5]) / det;
    inv[6] = (M[3] * M[7] - M[4] * M[6]) / det;
    inv[7] = (M[1] * M[6] - M[0] * M[7]) / det;
    inv[8] = (M[0] * M[4] - M[1] * M[3]) / det;
    fieldcal_apply(inv, (const float[3]){0.0f, 0.0f, 0.0f}, h->beta, shift);
    for (i = 0; i < 3; i++) {
        cal->mag_bias[i] += shift[i];
    }
    memcpy(cal->hard_iron_cov, h->P, sizeof h->P);
    fieldcal_hardiron_init(h, cal);
}
