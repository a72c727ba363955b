"""The C source of a force term's latent state integrated along a given motion: Heun's rule of
``pidyn.systems.terms.base.heun_along``, the same operations in the same order, on the latent
rate that ``pidyn.compiled.tape.record_latent`` records (the motion's x and x' its inputs 0 and 1).
Appended to the RK4 template; plain C, no braces to fill. The diagnosis's screening runs it for
every shape of its hysteretic and elastoplastic candidates along a whole record."""

SOURCE = r"""
/* Z (N, B, NS) from Z0 (B, NS): B parameter sets (P: B x NP), x sampled (N), x' sampled (V) or,
   with along_x, each interval's chord (x[i+1] - x[i]) / (t[i+1] - t[i]); S substeps. */
int heun(int N, int B, int S, int along_x, const double *T, const double *X, const double *V,
         const double *P, const double *K, const double *Z0, double *Z) {
    double I[NI], z[NS], k1[NS], k2[NS], u[NS], f0[NW > 1 ? NW : 2], f1[NW > 1 ? NW : 2];
    for (int b = 0; b < B; b++) {
        const double *Pb = P + (size_t)b * NP;
        prologue(Pb, K, I);
        for (int q = 0; q < NS; q++) z[q] = Z[(size_t)b * NS + q] = Z0[(size_t)b * NS + q];
        for (int i = 0; i + 1 < N; i++) {
            double h = (T[i + 1] - T[i]) / S;
            double chord = along_x ? (X[i + 1] - X[i]) / (T[i + 1] - T[i]) : 0.0;
            for (int j = 0; j < S; j++) {
                double a = (double)j / S, e = (double)(j + 1) / S;
                f0[0] = X[i] + a * (X[i + 1] - X[i]);
                f1[0] = X[i] + e * (X[i + 1] - X[i]);
                if (along_x) {
                    f0[1] = f1[1] = chord;
                } else {
                    f0[1] = V[i] + a * (V[i + 1] - V[i]);
                    f1[1] = V[i] + e * (V[i + 1] - V[i]);
                }
                rate(T[i], z, f0, Pb, I, K, k1);
                for (int q = 0; q < NS; q++) u[q] = z[q] + h * k1[q];
                rate(T[i], u, f1, Pb, I, K, k2);
                for (int q = 0; q < NS; q++) z[q] = z[q] + 0.5 * h * (k1[q] + k2[q]);
            }
            for (int q = 0; q < NS; q++) Z[((size_t)(i + 1) * B + b) * NS + q] = z[q];
        }
    }
    return 0;
}
"""
