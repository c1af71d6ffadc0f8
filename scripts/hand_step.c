/* Hand-written step loops of the midpoint rule for the bundled pendulum and double
 * pendulum: the baseline of scripts/bench_step.py (issue 23). What a careful person
 * writes by hand: the discrete Euler-Lagrange equation D2 L_d(q_{k-1}, q_k) +
 * D1 L_d(q_k, q_{k+1}) = 0 with L_d(a, b) = h L((a + b)/2, (b - a)/h), solved for
 * q_{k+1} by Newton's method from 2 q_k - q_{k-1}, the 1x1 and 2x2 systems in closed
 * form, stopped as symvi's loop is: when the update |dx|, or the error left after it
 * estimated from the contraction rate theta (theta/(1 - theta) |dx|), is at most
 * xtol (1 + |x|). Returns the Newton iterations taken in all, or -1 when a step did not
 * converge. */
#include <math.h>

static int converged(double dx, double previous, double x, double xtol, int it)
{
    const double tol = xtol * (1.0 + x), theta = dx / previous;
    return dx <= tol || (it > 0 && theta < 0.5 && theta / (1.0 - theta) * dx <= tol);
}

long hand_pendulum(const double *start, long n_steps, double h, double m, double l,
                   double g, double xtol, int maxiter, double *q)
{
    const double a = m * l * l / h, b = 0.5 * h * m * g * l;
    long total = 0;
    q[0] = start[0];
    q[1] = start[1];
    for (long k = 1; k < n_steps; ++k) {
        const double q0 = q[k - 1], q1 = q[k];
        const double p = a * (q1 - q0) - b * sin(0.5 * (q0 + q1));   /* D2 L_d(q0, q1) */
        double x = 2.0 * q1 - q0;
        double previous = INFINITY;
        int it = 0, done = 0;
        while (it < maxiter && !done) {
            const double s = 0.5 * (q1 + x);
            const double r = p - a * (x - q1) - b * sin(s);          /* + D1 L_d(q1, x) */
            const double dx = r / (a + 0.5 * b * cos(s));
            x += dx;
            done = converged(fabs(dx), previous, fabs(x), xtol, it);
            previous = fabs(dx);
            ++it;
        }
        if (!done) return -1;
        total += it;
        q[k + 1] = x;
    }
    return total;
}

/* L = (m1 + m2) l1^2 w1^2/2 + m2 l2^2 w2^2/2 + m2 l1 l2 w1 w2 cos(t1 - t2)
 *     + (m1 + m2) g l1 cos t1 + m2 g l2 cos t2;
 * D1 L_d = (h/2) L_q - L_v and D2 L_d = (h/2) L_q + L_v at the midpoint. */
static void lagrangian_derivatives(const double *qm, const double *v, double m1, double m2,
                                   double l1, double l2, double g, double *Lq, double *Lv,
                                   double *J, double h, int jacobian)
{
    const double k = m2 * l1 * l2, A = (m1 + m2) * l1 * l1, B = m2 * l2 * l2;
    const double G1 = (m1 + m2) * g * l1, G2 = m2 * g * l2;
    const double c = cos(qm[0] - qm[1]), s = sin(qm[0] - qm[1]);
    const double s1 = sin(qm[0]), s2 = sin(qm[1]);
    Lv[0] = A * v[0] + k * v[1] * c;
    Lv[1] = B * v[1] + k * v[0] * c;
    Lq[0] = -k * v[0] * v[1] * s - G1 * s1;
    Lq[1] = k * v[0] * v[1] * s - G2 * s2;
    if (!jacobian)
        return;
    /* d/dx of D1 L_d(q_k, x): (h/4) L_qq + (L_qv - L_vq)/2 - L_vv/h */
    const double w = k * v[0] * v[1] * c;
    const double qq[4] = {-w - G1 * cos(qm[0]), w, w, -w - G2 * cos(qm[1])};
    const double vq[4] = {-k * v[1] * s, k * v[1] * s, -k * v[0] * s, k * v[0] * s};
    const double vv[4] = {A, k * c, k * c, B};
    for (int i = 0; i < 2; ++i)
        for (int j = 0; j < 2; ++j)
            J[2 * i + j] = 0.25 * h * qq[2 * i + j] + 0.5 * (vq[2 * j + i] - vq[2 * i + j])
                           - vv[2 * i + j] / h;
}

long hand_double_pendulum(const double *start, long n_steps, double h, double m1,
                          double m2, double l1, double l2, double g, double xtol,
                          int maxiter, double *q)
{
    long total = 0;
    for (int i = 0; i < 4; ++i) q[i] = start[i];
    for (long k = 1; k < n_steps; ++k) {
        const double *q0 = q + 2 * (k - 1), *q1 = q + 2 * k;
        double qm[2], v[2], Lq[2], Lv[2], J[4], p[2], x[2];
        for (int i = 0; i < 2; ++i) {
            qm[i] = 0.5 * (q0[i] + q1[i]);
            v[i] = (q1[i] - q0[i]) / h;
        }
        lagrangian_derivatives(qm, v, m1, m2, l1, l2, g, Lq, Lv, J, h, 0);
        for (int i = 0; i < 2; ++i) {
            p[i] = 0.5 * h * Lq[i] + Lv[i];
            x[i] = 2.0 * q1[i] - q0[i];
        }
        double previous = INFINITY;
        int it = 0, done = 0;
        while (it < maxiter && !done) {
            for (int i = 0; i < 2; ++i) {
                qm[i] = 0.5 * (q1[i] + x[i]);
                v[i] = (x[i] - q1[i]) / h;
            }
            lagrangian_derivatives(qm, v, m1, m2, l1, l2, g, Lq, Lv, J, h, 1);
            const double r0 = p[0] + 0.5 * h * Lq[0] - Lv[0];
            const double r1 = p[1] + 0.5 * h * Lq[1] - Lv[1];
            const double det = J[0] * J[3] - J[1] * J[2];
            const double d0 = -(J[3] * r0 - J[1] * r1) / det;
            const double d1 = -(J[0] * r1 - J[2] * r0) / det;
            x[0] += d0;
            x[1] += d1;
            const double dn = fmax(fabs(d0), fabs(d1));
            done = converged(dn, previous, fmax(fabs(x[0]), fabs(x[1])), xtol, it);
            previous = dn;
            ++it;
        }
        if (!done) return -1;
        total += it;
        q[2 * (k + 1)] = x[0];
        q[2 * (k + 1) + 1] = x[1];
    }
    return total;
}
