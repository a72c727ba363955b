"""The C template of the compiled RK4 loop, filled by ``pidyn.compiled.codegen.source``
(``str.format``: the blocks in single braces are filled, C's own braces are doubled)."""

TEMPLATE = r"""/* A compiled RK4 loop for one system (pidyn.compiled.codegen fills the blocks in braces).
   Layouts (C order): tl (N), TT (N, B), F (N, FB, NW), ST (N-1, 2S+1, FB, NW) or NULL (FB: 1 where
   every trajectory reads the same excitation, else B),
   P (B, NP), dP (B, NP, D), Y0 (B, NS), dY0 (B, NS, D), Y (N, B, NS), dY (N, B, NS, D).
   run and run_d integrate trajectories b0 <= b < b1 of the B: each trajectory's arithmetic is its
   own, so threads that share the arrays and split the range give the same bits as one call. */
#include <math.h>
#include <stdlib.h>

#define NP {NP}
#define NS {NS}
#define NW {NW}
#define NI {NI}

static void prologue(const double *P, const double *K, double *I) {{
    (void)P; (void)K; (void)I;
    {prologue}
}}

static void prologue_d(int D, const double *P, const double *dP, const double *K, double *I, double *Id) {{
    (void)D; (void)P; (void)dP; (void)K; (void)I; (void)Id;
    {prologue_d}
}}

static void rate(double t, const double *y, const double *f, const double *P, const double *I,
                 const double *K, double *out) {{
    (void)t; (void)y; (void)f; (void)P; (void)I; (void)K;
    {rate}
}}

static void rate_d(int D, double t, const double *y, const double *yd, const double *f, const double *P,
                   const double *dP, const double *I, const double *Id, const double *K, double *out,
                   double *outd) {{
    (void)t; (void)y; (void)yd; (void)f; (void)P; (void)dP; (void)I; (void)Id; (void)K;
    {rate_d}
}}

/* the excitation at the start, middle and end of substep s of interval i (pidyn.integrate._stage_inputs) */
static void inputs(int B, int S, int i, int s, int b, const double *F, const double *ST, double *fa,
                   double *fm, double *fb) {{
    if (ST) {{
        const double *row = ST + (size_t)i * (2 * S + 1) * B * NW;
        for (int q = 0; q < NW; q++) {{
            fa[q] = row[((size_t)(2 * s) * B + b) * NW + q];
            fm[q] = row[((size_t)(2 * s + 1) * B + b) * NW + q];
            fb[q] = row[((size_t)(2 * s + 2) * B + b) * NW + q];
        }}
        return;
    }}
    for (int q = 0; q < NW; q++) {{
        double f0 = F[((size_t)i * B + b) * NW + q], f1 = F[((size_t)(i + 1) * B + b) * NW + q];
        double df = (f1 - f0) / S;
        fa[q] = f0 + s * df;
        fm[q] = fa[q] + 0.5 * df;
        fb[q] = fa[q] + df;
    }}
}}

/* one evaluation of the state rate (a variable-step integrator's right-hand side) */
int n_invariants(void) {{ return NI; }}
void invariants(const double *P, const double *K, double *I) {{ prologue(P, K, I); }}
void rhs(double t, const double *y, const double *f, const double *P, const double *I, const double *K,
         double *out) {{
    rate(t, y, f, P, I, K, out);
}}

/* the same with the excitation read from its samples as np.interp(t, grid, acc, left=0, right=0) reads
   them (one input, a uniform grid of step dt): no call back into Python for it */
void rhs_sampled(double t, const double *y, const double *acc, int n, double dt, const double *P, const double *I,
                 const double *K, double *out) {{
    double f[NW > 0 ? NW : 1];
    if (!(t >= 0.0) || t > (n - 1) * dt) {{
        f[0] = 0.0;
    }} else if (t == (n - 1) * dt) {{
        f[0] = acc[n - 1];
    }} else {{
        int j = (int)(t / dt);
        if (j > n - 2) j = n - 2;
        while (j > 0 && j * dt > t) j--;
        while (j < n - 2 && (j + 1) * dt <= t) j++;
        double x0 = j * dt, x1 = (j + 1) * dt;
        double slope = (acc[j + 1] - acc[j]) / (x1 - x0);
        f[0] = slope * (t - x0) + acc[j];
        if (f[0] != f[0]) {{
            f[0] = slope * (t - x1) + acc[j + 1];
            if (f[0] != f[0] && acc[j] == acc[j + 1]) f[0] = acc[j];
        }}
    }}
    rate(t, y, f, P, I, K, out);
}}

int run(int N, int B, int b0, int b1, int S, int FB, const double *tl, const double *TT, const double *F, const double *ST,
        const double *P, const double *K, const double *Y0, double *Y) {{
    double I[NI], y[NS], k1[NS], k2[NS], k3[NS], k4[NS], u[NS], fa[NW], fm[NW], fb[NW];
    for (int b = b0; b < b1; b++) {{
        const double *Pb = P + (size_t)b * NP;
        prologue(Pb, K, I);
        for (int j = 0; j < NS; j++) {{
            y[j] = Y0[(size_t)b * NS + j];
            Y[(size_t)b * NS + j] = y[j];
        }}
        for (int i = 0; i < N - 1; i++) {{
            double h = (tl[i + 1] - tl[i]) / S;
            for (int s = 0; s < S; s++) {{
                double ta = TT[(size_t)i * B + b] + s * h;
                inputs(FB, S, i, s, FB == 1 ? 0 : b, F, ST, fa, fm, fb);
                rate(ta, y, fa, Pb, I, K, k1);
                for (int j = 0; j < NS; j++) u[j] = y[j] + (0.5 * h) * k1[j];
                rate(ta + 0.5 * h, u, fm, Pb, I, K, k2);
                for (int j = 0; j < NS; j++) u[j] = y[j] + (0.5 * h) * k2[j];
                rate(ta + 0.5 * h, u, fm, Pb, I, K, k3);
                for (int j = 0; j < NS; j++) u[j] = y[j] + h * k3[j];
                rate(ta + h, u, fb, Pb, I, K, k4);
                for (int j = 0; j < NS; j++) y[j] = y[j] + (h / 6.0) * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
            }}
            for (int j = 0; j < NS; j++) Y[((size_t)(i + 1) * B + b) * NS + j] = y[j];
        }}
    }}
    return 0;
}}

int run_d(int N, int B, int b0, int b1, int S, int FB, int D, const double *tl, const double *TT, const double *F, const double *ST,
          const double *P, const double *dP, const double *K, const double *Y0, const double *dY0, double *Y,
          double *dY) {{
    size_t nd = (size_t)NS * D;
    double *buf = malloc(sizeof(double) * ((size_t)NI * D + 6 * nd + 1));
    if (!buf) return 1;
    double *Id = buf, *yd = Id + (size_t)NI * D, *k1d = yd + nd, *k2d = k1d + nd, *k3d = k2d + nd;
    double *k4d = k3d + nd, *ud = k4d + nd;
    double I[NI], y[NS], k1[NS], k2[NS], k3[NS], k4[NS], u[NS], fa[NW], fm[NW], fb[NW];
    for (int b = b0; b < b1; b++) {{
        const double *Pb = P + (size_t)b * NP, *dPb = dP + (size_t)b * NP * D;
        prologue_d(D, Pb, dPb, K, I, Id);
        for (int j = 0; j < NS; j++) {{
            y[j] = Y0[(size_t)b * NS + j];
            Y[(size_t)b * NS + j] = y[j];
        }}
        for (size_t q = 0; q < nd; q++) {{
            yd[q] = dY0[(size_t)b * nd + q];
            dY[(size_t)b * nd + q] = yd[q];
        }}
        for (int i = 0; i < N - 1; i++) {{
            double h = (tl[i + 1] - tl[i]) / S;
            for (int s = 0; s < S; s++) {{
                double ta = TT[(size_t)i * B + b] + s * h;
                inputs(FB, S, i, s, FB == 1 ? 0 : b, F, ST, fa, fm, fb);
                rate_d(D, ta, y, yd, fa, Pb, dPb, I, Id, K, k1, k1d);
                for (int j = 0; j < NS; j++) u[j] = y[j] + (0.5 * h) * k1[j];
                for (size_t q = 0; q < nd; q++) ud[q] = yd[q] + k1d[q] * (0.5 * h);
                rate_d(D, ta + 0.5 * h, u, ud, fm, Pb, dPb, I, Id, K, k2, k2d);
                for (int j = 0; j < NS; j++) u[j] = y[j] + (0.5 * h) * k2[j];
                for (size_t q = 0; q < nd; q++) ud[q] = yd[q] + k2d[q] * (0.5 * h);
                rate_d(D, ta + 0.5 * h, u, ud, fm, Pb, dPb, I, Id, K, k3, k3d);
                for (int j = 0; j < NS; j++) u[j] = y[j] + h * k3[j];
                for (size_t q = 0; q < nd; q++) ud[q] = yd[q] + k3d[q] * h;
                rate_d(D, ta + h, u, ud, fb, Pb, dPb, I, Id, K, k4, k4d);
                for (int j = 0; j < NS; j++) y[j] = y[j] + (h / 6.0) * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
                for (size_t q = 0; q < nd; q++)
                    yd[q] = yd[q] + (k1d[q] + k2d[q] * 2.0 + k3d[q] * 2.0 + k4d[q]) * (h / 6.0);
            }}
            for (int j = 0; j < NS; j++) Y[((size_t)(i + 1) * B + b) * NS + j] = y[j];
            for (size_t q = 0; q < nd; q++) dY[((size_t)(i + 1) * B + b) * nd + q] = yd[q];
        }}
    }}
    free(buf);
    return 0;
}}
"""
