"""The C source of the compiled ground truth: Dormand and Prince's 5(4) pair with step-size control
(Hairer, Norsett and Wanner, *Solving Ordinary Differential Equations I*, 2nd ed., II.5), on the
state rate of ``pidyn.compiled.codegen`` with the excitation read from its samples, one column
per input (a ground motion's acceleration; a support's acceleration and velocity). Appended to
the RK4 template; plain C, no braces to fill.

Every step ends on the record's samples (the excitation's kinks) and on the output times, as
LSODA's ``hmax`` of one sample made it do; within them the step follows the error estimate,
rejected steps shrink it, and a step at the floor of double precision is taken as it is (a
discontinuous force term, such as a friction's sign, is crossed, not fought).
"""

SOURCE = r"""
/* Dormand-Prince 5(4), FSAL, the error of the 4th-order embedded solution per step below
   atol + rtol max(|y|, |y_new|) in the root mean square over the states; Y and DY: the states and
   their rates at the output times T. Returns 0, -1 when
   max_evals evaluations did not reach the end, -2 on a value that is not finite. */
/* the excitation's W columns at t, each linear between its samples (cols: n x NW, step dt), as
   np.interp reads it: zero before the record, after it zero or (hold[q]) its last sample */
static void read_inputs(double t, const double *cols, int n, double dt, const int *hold, double *f) {
    if (!(t >= 0.0) || t > (n - 1) * dt) {
        for (int q = 0; q < NW; q++) f[q] = (t > 0.0 && hold[q]) ? cols[(size_t)(n - 1) * NW + q] : 0.0;
        return;
    }
    int j = (int)(t / dt);
    if (j > n - 2) j = n - 2;
    while (j > 0 && j * dt > t) j--;
    while (j < n - 2 && (j + 1) * dt <= t) j++;
    double x0 = j * dt, x1 = (j + 1) * dt;
    for (int q = 0; q < NW; q++) {
        double c0 = cols[(size_t)j * NW + q], c1 = cols[(size_t)(j + 1) * NW + q];
        if (t == (n - 1) * dt) {
            f[q] = c1;
            continue;
        }
        double slope = (c1 - c0) / (x1 - x0);
        f[q] = slope * (t - x0) + c0;
        if (f[q] != f[q]) {
            f[q] = slope * (t - x1) + c1;
            if (f[q] != f[q] && c0 == c1) f[q] = c0;
        }
    }
}

static void stage(double t, const double *y, const double *cols, int n, double dt, const int *hold,
                  const double *P, const double *I, const double *K, double *out) {
    double f[NW > 0 ? NW : 1];
    read_inputs(t, cols, n, dt, hold, f);
    rate(t, y, f, P, I, K, out);
}

static double dp_norm(const double *e, const double *y, const double *yn, double rtol, double atol) {
    double s = 0.0;
    for (int j = 0; j < NS; j++) {
        double a = fabs(y[j]) > fabs(yn[j]) ? fabs(y[j]) : fabs(yn[j]);
        double r = e[j] / (atol + rtol * a);
        s += r * r;
    }
    return sqrt(s / NS);
}

int truth(int N, const double *T, const double *cols, int n, double dt, const int *hold, const double *P,
          const double *K, const double *Y0, double rtol, double atol, long max_evals, double *Y,
          double *DY) {
    static const double c2 = 1.0 / 5, c3 = 3.0 / 10, c4 = 4.0 / 5, c5 = 8.0 / 9;
    static const double a21 = 1.0 / 5, a31 = 3.0 / 40, a32 = 9.0 / 40, a41 = 44.0 / 45, a42 = -56.0 / 15,
                        a43 = 32.0 / 9, a51 = 19372.0 / 6561, a52 = -25360.0 / 2187, a53 = 64448.0 / 6561,
                        a54 = -212.0 / 729, a61 = 9017.0 / 3168, a62 = -355.0 / 33, a63 = 46732.0 / 5247,
                        a64 = 49.0 / 176, a65 = -5103.0 / 18656, a71 = 35.0 / 384, a73 = 500.0 / 1113,
                        a74 = 125.0 / 192, a75 = -2187.0 / 6784, a76 = 11.0 / 84;
    static const double e1 = 71.0 / 57600, e3 = -71.0 / 16695, e4 = 71.0 / 1920, e5 = -17253.0 / 339200,
                        e6 = 22.0 / 525, e7 = -1.0 / 40;
    double I[NI], y[NS], yn[NS], u[NS], e[NS], k1[NS], k2[NS], k3[NS], k4[NS], k5[NS], k6[NS], k7[NS];
    prologue(P, K, I);
    for (int j = 0; j < NS; j++) y[j] = Y[j] = Y0[j];
    double t = T[0];
    stage(t, y, cols, n, dt, hold, P, I, K, k1);
    for (int j = 0; j < NS; j++) DY[j] = k1[j];
    long evals = 1;
    double h = dt < T[1] - T[0] ? dt : T[1] - T[0];
    for (int i = 0; i + 1 < N; i++) {
        while (t < T[i + 1]) {
            /* the next kink of the excitation (a sample) or the output time, whichever comes first */
            double end = (floor(t / dt) + 1.0) * dt;
            if (end - t < 1e-9 * dt) end += dt;
            if (end > T[i + 1] - 1e-9 * dt) end = T[i + 1];
            while (t < end) {
                double hh = h < end - t ? h : end - t;
                if (end - (t + hh) < 1e-9 * dt) hh = end - t;
                for (int j = 0; j < NS; j++) u[j] = y[j] + hh * a21 * k1[j];
                stage(t + c2 * hh, u, cols, n, dt, hold, P, I, K, k2);
                for (int j = 0; j < NS; j++) u[j] = y[j] + hh * (a31 * k1[j] + a32 * k2[j]);
                stage(t + c3 * hh, u, cols, n, dt, hold, P, I, K, k3);
                for (int j = 0; j < NS; j++) u[j] = y[j] + hh * (a41 * k1[j] + a42 * k2[j] + a43 * k3[j]);
                stage(t + c4 * hh, u, cols, n, dt, hold, P, I, K, k4);
                for (int j = 0; j < NS; j++)
                    u[j] = y[j] + hh * (a51 * k1[j] + a52 * k2[j] + a53 * k3[j] + a54 * k4[j]);
                stage(t + c5 * hh, u, cols, n, dt, hold, P, I, K, k5);
                for (int j = 0; j < NS; j++)
                    u[j] = y[j] + hh * (a61 * k1[j] + a62 * k2[j] + a63 * k3[j] + a64 * k4[j] + a65 * k5[j]);
                stage(t + hh, u, cols, n, dt, hold, P, I, K, k6);
                for (int j = 0; j < NS; j++)
                    yn[j] = y[j] + hh * (a71 * k1[j] + a73 * k3[j] + a74 * k4[j] + a75 * k5[j] + a76 * k6[j]);
                double tn = (hh == end - t) ? end : t + hh;
                stage(tn, yn, cols, n, dt, hold, P, I, K, k7);
                evals += 6;
                for (int j = 0; j < NS; j++)
                    e[j] = hh * (e1 * k1[j] + e3 * k3[j] + e4 * k4[j] + e5 * k5[j] + e6 * k6[j] + e7 * k7[j]);
                double err = dp_norm(e, y, yn, rtol, atol);
                if (err != err) return -2;
                double floor_h = 1e-14 * (fabs(t) > 1.0 ? fabs(t) : 1.0);
                if (err <= 1.0 || hh <= floor_h) {
                    t = tn;
                    for (int j = 0; j < NS; j++) {
                        y[j] = yn[j];
                        k1[j] = k7[j];
                    }
                    double grow = err > 0.0 ? 0.9 * pow(err, -0.2) : 5.0;
                    grow = grow > 5.0 ? 5.0 : (grow < 0.2 ? 0.2 : grow);
                    double proposed = hh * grow;
                    if (proposed > h || hh == h) h = proposed; /* a step cut short by a kink keeps its size */
                } else {
                    double shrink = 0.9 * pow(err, -0.2);
                    h = hh * (shrink < 0.2 ? 0.2 : shrink);
                    if (h < floor_h) h = floor_h;
                }
                if (evals > max_evals) return -1;
            }
        }
        for (int j = 0; j < NS; j++) {
            if (!(fabs(y[j]) <= 1e300)) return -2;
            Y[(size_t)(i + 1) * NS + j] = y[j];
            DY[(size_t)(i + 1) * NS + j] = k1[j]; /* the last stage, at T[i + 1] exactly */
        }
    }
    return 0;
}
"""
