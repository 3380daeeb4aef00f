/* Golden-vector check of an observer exported by `jaxobs export` (C99).
 *
 *   cc -std=c99 -O2 -Wall -Werror -pedantic observer.c test_main.c -lm -o jx_test && ./jx_test golden.csv
 *
 * golden.csv: a header line, then per step the JX_NU inputs fed to jx_step and the JX_NY
 * outputs the JAX step returned (float32, printed with 9 significant digits).  Every output
 * of every step is compared:
 *
 *     err = |y_C - y_golden| / (1 + |y_golden|)      (angles: the difference wrapped to [-pi, pi])
 *
 * Prints "max_rel_err=E step=N output=K rows=R" and exits 0 if E <= JX_TOL, 1 above it
 * (or on a non-finite output), 2 if the file cannot be read or has the wrong columns.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "observer.h"

#define JX_TOL 1e-4
#define JX_LINE 8192

static const int jx_is_angle[JX_NY] = JX_Y_IS_ANGLE;

static int jx_columns(const char *line)
{
    int n = 1;
    for (; *line != '\0'; ++line) {
        if (*line == ',') ++n;
    }
    return n;
}

int main(int argc, char **argv)
{
    const char *path = argc > 1 ? argv[1] : "golden.csv";
    const double two_pi = 6.283185307179586;
    char line[JX_LINE];
    float u[JX_NU], y[JX_NY];
    double worst = 0.0;
    long rows = 0, worst_step = -1;
    int worst_out = -1, i;
    jx_state s;
    FILE *fp = fopen(path, "r");

    if (fp == NULL) {
        fprintf(stderr, "jx_test: cannot open %s\n", path);
        return 2;
    }
    if (fgets(line, sizeof line, fp) == NULL || jx_columns(line) != JX_NU + JX_NY) {
        fprintf(stderr, "jx_test: %s: the header must have JX_NU + JX_NY = %d columns\n", path, JX_NU + JX_NY);
        fclose(fp);
        return 2;
    }
    jx_init(&s);
    while (fgets(line, sizeof line, fp) != NULL) {
        char *p = line, *end;
        if (line[0] == '\n' || line[0] == '\0') continue;
        for (i = 0; i < JX_NU; ++i) {
            u[i] = strtof(p, &end);
            if (end == p) break;
            p = (*end == ',') ? end + 1 : end;
        }
        if (i < JX_NU) {
            fprintf(stderr, "jx_test: %s: row %ld: cannot read input %d\n", path, rows + 1, i);
            fclose(fp);
            return 2;
        }
        jx_step(&s, u, y);
        for (i = 0; i < JX_NY; ++i) {
            double g = strtod(p, &end), d, err;
            if (end == p) {
                fprintf(stderr, "jx_test: %s: row %ld: cannot read output %d\n", path, rows + 1, i);
                fclose(fp);
                return 2;
            }
            p = (*end == ',') ? end + 1 : end;
            d = (double)y[i] - g;
            if (jx_is_angle[i]) d = remainder(d, two_pi);
            err = fabs(d) / (1.0 + fabs(g));
            if (!(err <= worst)) { /* also catches NaN */
                worst = isnan(err) ? HUGE_VAL : err;
                worst_step = rows;
                worst_out = i;
            }
        }
        ++rows;
    }
    fclose(fp);
    if (rows == 0) {
        fprintf(stderr, "jx_test: %s: no rows\n", path);
        return 2;
    }
    printf("max_rel_err=%.3e step=%ld output=%d rows=%ld tol=%.0e %s\n", worst, worst_step, worst_out, rows, JX_TOL,
           worst <= JX_TOL ? "PASS" : "FAIL");
    return worst <= JX_TOL ? 0 : 1;
}
