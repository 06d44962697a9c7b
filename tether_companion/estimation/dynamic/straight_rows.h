/* observability.unmodelled_position_rows's statements in C, in its order (the straight cable's
 * unmodelled-force rows), for the C twins that read them at every IMU tick's status:
 * bound_core.c (the rows alone) and status_core.c (within the published covariance's added
 * terms). Build with -ffp-contract=off.
 */
#ifndef TETHER_STRAIGHT_ROWS_H
#define TETHER_STRAIGHT_ROWS_H

#include <math.h>

/* observability.MIN_TENSION_N [N] (tests/test_bound_core.py checks the two are equal) */
#define MIN_TENSION_N 0.01

/* The 3x3 rows, row-major, into r (zeros at the anchor). The divisor is at least
 * MIN_TENSION_N, or NaN: never zero (no ZeroDivisionError to mirror). */
static inline void
straight_rows(double n, double e, double d, double tension_n, double force_std_n,
              double length_std_m, double *r)
{
    double distance = sqrt(n * n + e * e + d * d);
    if (distance == 0.0) {
        for (int i = 0; i < 9; i++)
            r[i] = 0.0;
        return;
    }
    double u0 = n / distance, u1 = e / distance, u2 = d / distance;
    double an0 = 1.0 - u0 * u0, an1 = -u1 * u0, an2 = -u2 * u0;
    double ae0 = -u0 * u1, ae1 = 1.0 - u1 * u1, ae2 = -u2 * u1;
    double gain = distance * force_std_n / (MIN_TENSION_N > tension_n ? MIN_TENSION_N
                                                                        : tension_n);
    double g = gain * gain, w = length_std_m * length_std_m;
    r[0] = g * (an0 * an0 + ae0 * ae0) + w * u0 * u0;
    r[1] = g * (an0 * an1 + ae0 * ae1) + w * u0 * u1;
    r[2] = g * (an0 * an2 + ae0 * ae2) + w * u0 * u2;
    r[3] = g * (an1 * an0 + ae1 * ae0) + w * u1 * u0;
    r[4] = g * (an1 * an1 + ae1 * ae1) + w * u1 * u1;
    r[5] = g * (an1 * an2 + ae1 * ae2) + w * u1 * u2;
    r[6] = g * (an2 * an0 + ae2 * ae0) + w * u2 * u0;
    r[7] = g * (an2 * an1 + ae2 * ae1) + w * u2 * u1;
    r[8] = g * (an2 * an2 + ae2 * ae2) + w * u2 * u2;
}

#endif
