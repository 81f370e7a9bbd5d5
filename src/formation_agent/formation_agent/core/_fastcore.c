/* The compiled certified first-crossing search of formation_agent.core (docs/COMPILED_CORE.md).
 *
 * One function, advance(), runs CrossingSearch.advance (crossing.py) for an agent on the
 * plain-float path (p <= 3): the step loop, e_i and its rate (Eta1Agent/Eta2Agent._fast_probe),
 * their bounds (_fast_bounds), the last step (_finish) and the polish (_root_in_bracket), with
 * ETA-2's closed forms (Eta2Agent._closed_form, closed_form.z_minus_one_plus_exp_float).
 * Every expression is the Python one, operation for operation and in its order (Python
 * evaluates a * b * c as (a * b) * c, and so does C); min/max are Python's (the first argument
 * unless the second is strictly smaller/larger); exp, expm1 and sqrt are the libm functions
 * that CPython's math module calls. Built with -O2 -ffp-contract=off and without -ffast-math
 * (setup.py), the results are the very floats of the pure-Python path, which
 * tests/formation_agent/core/test_compiled.py checks bit for bit.
 *
 * The constants (growth factor, step limit, the polish's 4 ulps, the gap fraction, the series)
 * are handed over once by formation_agent.core.compiled (configure), so they have one source.
 * Errors the Python path raises with a message are returned as a tuple for compiled.py to
 * raise in the same words; an overflow of exp/expm1 raises OverflowError('math range error')
 * as math.exp does.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>
#include <structmember.h>

#define WIDTH1 9  /* Eta1Agent._row: anchor, y0, y1, y2, v0, v1, v2, speed, capacity */
#define WIDTH2 11 /* Eta2Agent._row: anchor, y0, y1, y2, q0, q1, q2, u0, u1, u2, capacity */
#define N_SERIES 11

static double GROWTH = 4.0, RTOL = 0.0, GAP_FRACTION = 0.125, SERIES_LIMIT = 0.1;
static long MAX_STEPS = 0;
static double SERIES[N_SERIES];
static int configured = 0;

/* Python's min(a, b) and max(a, b) for two floats. */
static inline double py_min(double a, double b) { return b < a ? b : a; }
static inline double py_max(double a, double b) { return b > a ? b : a; }

enum { OK = 0, ERR_RANGE = 1, ERR_OVERFLOW = 2 };

typedef struct {
    int kind; /* 1: ETA-1, 2: ETA-2 */
    Py_ssize_t m;
    double *rows;  /* m rows of WIDTH1 / WIDTH2 */
    double *probe; /* ETA-1: radius per edge; ETA-2: (r, ||q||, ||q'||, c) per edge */
    double *speeds;
    double cap; /* ETA-1: the span limit of _span_within_capacity */
    double u_off[3];
    double control_norm;
    double k1, k2, k3;
    Py_ssize_t bad_k; /* ERR_RANGE: the edge, its length and capacity */
    double bad_r, bad_c;
} Model;

/* math.exp / math.expm1: an infinite result of a finite argument is an OverflowError. */
static inline int checked(double x, double y) { return isinf(y) && isfinite(x) ? ERR_OVERFLOW : OK; }

static inline int out_of_range(Model *md, Py_ssize_t k, double r, double c) {
    md->bad_k = k;
    md->bad_r = r;
    md->bad_c = c;
    return ERR_RANGE;
}

/* The tail of both probes (_fast_probe's return): e plus the command's offset, and the rate. */
static inline int probe_out(const Model *md, double e0, double e1, double e2, double d0, double d1, double d2,
                            double *out) {
    out[0] = e0 + md->u_off[0];
    out[1] = e1 + md->u_off[1];
    out[2] = e2 + md->u_off[2];
    out[3] = d0;
    out[4] = d1;
    out[5] = d2;
    return OK;
}

/* Eta1Agent._fast_probe: e and (with_rate) its rate, padded to three components. */
static int probe1(Model *md, double t, int with_rate, double *out) {
    double e0 = 0.0, e1 = 0.0, e2 = 0.0, d0 = 0.0, d1 = 0.0, d2 = 0.0;
    double cap = INFINITY;
    for (Py_ssize_t k = 0; k < md->m; k++) {
        const double *row = md->rows + k * WIDTH1;
        double anchor = row[0], ya0 = row[1], ya1 = row[2], ya2 = row[3];
        double v0 = row[4], v1 = row[5], v2 = row[6], speed = row[7], c = row[8];
        double s = t - anchor;
        double y0 = ya0 + s * v0; /* (statexixj) */
        double y1 = ya1 + s * v1;
        double y2 = ya2 + s * v2;
        double r = sqrt(y0 * y0 + y1 * y1 + y2 * y2);
        double gap = c - r;
        if (gap <= 0.0)
            return out_of_range(md, k, r, c);
        double w = (2.0 * c - r) / (gap * gap); /* (fij) */
        e0 += w * y0;
        e1 += w * y1;
        e2 += w * y2;
        if (!with_rate)
            continue;
        double radial = r > 0.0 ? (y0 * v0 + y1 * v1 + y2 * v2) / r : 0.0;
        double f = (3.0 * c - r) / (gap * gap * gap) * radial; /* (hij) */
        d0 += f * y0 + w * v0;
        d1 += f * y1 + w * v1;
        d2 += f * y2 + w * v2;
        md->probe[k] = r;
        if (speed > 0.0) {
            double limit = GAP_FRACTION * gap / speed;
            cap = py_min(cap, limit);
        }
    }
    if (with_rate)
        md->cap = cap;
    return probe_out(md, e0, e1, e2, d0, d1, d2, out);
}

/* Eta1Agent._fast_bounds */
static void bounds1(Model *md, double span, double size, double *out) {
    span = py_min(span, md->cap);
    double rate = 0.0, curv = 0.0, reach_sum = 0.0;
    for (Py_ssize_t k = 0; k < md->m; k++) {
        const double *row = md->rows + k * WIDTH1;
        double r = md->probe[k], speed = row[7], c = row[8];
        double reach = r + span * speed;
        double gap = c - reach;
        double gap3 = gap * gap * gap;
        rate += 2.0 * c * c / gap3 * speed; /* (gij), (dotnormei) */
        curv += (reach * ((8.0 * c - 2.0 * reach) / (gap3 * gap)) + 3.0 * ((3.0 * c - reach) / gap3)) * speed *
                speed;
        reach_sum += (2.0 * c - reach) / (gap * gap) * reach;
    }
    out[0] = span;
    out[1] = py_min(size + rate * span, md->control_norm + reach_sum);
    out[2] = rate;
    out[3] = curv;
}

/* closed_form.z_minus_one_plus_exp_float */
static inline double series(double z) {
    const double *c = SERIES;
    double acc = c[8] - z * (c[9] - z * c[10]);
    return z * z * (c[0] - z * (c[1] - z * (c[2] - z * (c[3] - z * (c[4] - z * (c[5] - z * (c[6] - z * (c[7] - z * acc))))))));
}

/* Eta2Agent._fast_probe, with Eta2Agent._closed_form written out. */
static int probe2(Model *md, double t, int with_rate, double *out) {
    double k1 = md->k1, k2 = md->k2, k3 = md->k3;
    double e0 = 0.0, e1 = 0.0, e2 = 0.0, d0 = 0.0, d1 = 0.0, d2 = 0.0;
    double lag = 0.0, ramp = 0.0, fade = 0.0, last_anchor = 0.0;
    int have_anchor = 0;
    for (Py_ssize_t k = 0; k < md->m; k++) {
        const double *row = md->rows + k * WIDTH2;
        double anchor = row[0], ya0 = row[1], ya1 = row[2], ya2 = row[3];
        double qa0 = row[4], qa1 = row[5], qa2 = row[6], u0 = row[7], u1 = row[8], u2 = row[9], c = row[10];
        if (!have_anchor || anchor != last_anchor) {
            double z = k3 * (t - anchor);
            double em = expm1(-z);
            if (checked(-z, em))
                return ERR_OVERFLOW;
            double decay = -em; /* 1 - e^{-z} */
            double rmp = fabs(z) < SERIES_LIMIT ? series(z) : z - decay;
            lag = decay / k3;
            ramp = rmp / (k3 * k3);
            fade = 1.0 - decay;
            last_anchor = anchor;
            have_anchor = 1;
        }
        double y0 = ya0 + lag * qa0 + ramp * u0; /* (statexixjd) */
        double y1 = ya1 + lag * qa1 + ramp * u1;
        double y2 = ya2 + lag * qa2 + ramp * u2;
        double q0 = fade * qa0 + lag * u0; /* (stateqiqj) */
        double q1 = fade * qa1 + lag * u1;
        double q2 = fade * qa2 + lag * u2;
        double r = sqrt(y0 * y0 + y1 * y1 + y2 * y2);
        double gap = c - r;
        if (gap <= 0.0)
            return out_of_range(md, k, r, c);
        double w = (2.0 * c - r) / (gap * gap); /* (fij) */
        double m0 = k1 * y0 + k2 * q0;
        double m1 = k1 * y1 + k2 * q1;
        double m2 = k1 * y2 + k2 * q2;
        e0 += w * m0;
        e1 += w * m1;
        e2 += w * m2;
        if (!with_rate)
            continue;
        double a0 = u0 - k3 * q0;
        double a1 = u1 - k3 * q1;
        double a2 = u2 - k3 * q2;
        double radial = r > 0.0 ? (y0 * q0 + y1 * q1 + y2 * q2) / r : 0.0;
        double f = (3.0 * c - r) / (gap * gap * gap) * radial; /* (hij) */
        d0 += f * m0 + w * (k1 * q0 + k2 * a0);
        d1 += f * m1 + w * (k1 * q1 + k2 * a1);
        d2 += f * m2 + w * (k1 * q2 + k2 * a2);
        double *p = md->probe + 4 * k;
        p[0] = r;
        p[1] = sqrt(q0 * q0 + q1 * q1 + q2 * q2);
        p[2] = sqrt(a0 * a0 + a1 * a1 + a2 * a2);
        p[3] = c;
    }
    return probe_out(md, e0, e1, e2, d0, d1, d2, out);
}

/* Eta2Agent._fast_bounds */
static int bounds2(Model *md, double span, double size, double *out) {
    double k1 = md->k1, k2 = md->k2, k3 = md->k3;
    double em = expm1(-k3 * span);
    if (checked(-k3 * span, em))
        return ERR_OVERFLOW;
    double growth = -em / k3;
    for (Py_ssize_t k = 0; k < md->m; k++) {
        const double *p = md->probe + 4 * k;
        double r = p[0], q_now = p[1], accel = p[2], c = p[3];
        double speed = q_now + growth * accel;
        if (speed > 0.0)
            span = py_min(span, GAP_FRACTION * (c - r) / speed);
        md->speeds[k] = speed;
    }
    double rate = 0.0, curv_y = 0.0, curv_q = 0.0, reach_sum = 0.0;
    int kink = 0;
    for (Py_ssize_t k = 0; k < md->m; k++) {
        const double *p = md->probe + 4 * k;
        double r = p[0], accel = p[2], c = p[3], speed = md->speeds[k];
        double reach = r + span * speed;
        double gap = c - reach;
        double gap3 = gap * gap * gap;
        double w = (2.0 * c - reach) / (gap * gap);
        double h = (3.0 * c - reach) / gap3;
        double g = 2.0 * c * c / gap3;
        double second = (8.0 * c - 2.0 * reach) / (gap3 * gap);
        double speed_sq = speed * speed;
        rate += k1 * g * speed + k2 * (h * speed_sq + w * accel);
        curv_y += (reach * second + 3.0 * h) * speed_sq + g * accel;
        if (speed > 0.0) {
            double low = r - span * speed;
            if (low <= 0.0) {
                kink = 1;
            } else {
                double omega_ddot = second * speed_sq + h * (speed_sq / low + accel);
                curv_q += omega_ddot * speed + 2.0 * h * speed * accel + w * k3 * accel;
            }
        } else {
            curv_q += w * k3 * accel;
        }
        reach_sum += w * (k1 * reach + k2 * speed);
    }
    out[0] = span;
    out[1] = py_min(size + rate * span, md->control_norm + reach_sum);
    out[2] = rate;
    out[3] = kink ? INFINITY : k1 * curv_y + k2 * curv_q;
    return OK;
}

static inline int probe(Model *md, double t, int with_rate, double *out) {
    return md->kind == 1 ? probe1(md, t, with_rate, out) : probe2(md, t, with_rate, out);
}

static inline int bounds(Model *md, double span, double size, double *out) {
    if (md->kind == 1) {
        bounds1(md, span, size, out);
        return OK;
    }
    return bounds2(md, span, size, out);
}

/* The agent's error_norm: ||e(t)|| from a probe without the rate. */
static inline int norm(Model *md, double t, double *out) {
    double e[6];
    int status = probe(md, t, 0, e);
    if (status)
        return status;
    *out = sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
    return OK;
}

typedef struct {
    double alpha, beta, floor, limit, tolerance;
} Search;

/* CrossingSearch._scale */
static inline int scale_at(const Search *s, double a, double *out) {
    if (s->floor == 0.0) {
        double x = s->beta * a, y = exp(x);
        if (checked(x, y))
            return ERR_OVERFLOW;
        *out = y / s->alpha;
        return OK;
    }
    double x = -s->beta * a, y = exp(x);
    if (checked(x, y))
        return ERR_OVERFLOW;
    *out = 1.0 / (s->floor + s->alpha * y);
    return OK;
}

/* The margin r(t) - S ||e(t)|| of _finish. */
static inline int margin(Model *md, double beta, double a, double share, double fade, double scale, double t,
                         double *out) {
    double x = -beta * (t - a), y = exp(x), n;
    if (checked(x, y))
        return ERR_OVERFLOW;
    int status = norm(md, t, &n);
    if (status)
        return status;
    *out = share + fade * y - scale * n;
    return OK;
}

/* crossing._root_in_bracket over the margin (max_iterations = 200). */
static int root_in_bracket(Model *md, double beta, double a0, double share, double fade, double scale, double a,
                           double fa, double b, double fb, double *out) {
    int kept = 0;
    double weight_a = fa, weight_b = fb, x = a;
    for (int i = 0; i < 200; i++) {
        double big = py_max(py_max(fabs(a), fabs(b)), 1e-300);
        if (b - a <= RTOL * big)
            break;
        double previous = x;
        x = b - weight_b * ((b - a) / (weight_b - weight_a));
        if (!(a < x && x < b))
            x = a + 0.5 * (b - a);
        double fx;
        int status = margin(md, beta, a0, share, fade, scale, x, &fx);
        if (status)
            return status;
        if (fx == 0.0) {
            *out = x;
            return OK;
        }
        if ((fx > 0.0) == (fa > 0.0)) {
            a = x;
            fa = fx;
            weight_a = fx;
            if (kept == 1)
                weight_b *= 0.5;
            kept = 1;
        } else {
            b = x;
            fb = fx;
            weight_b = fx;
            if (kept == -1)
                weight_a *= 0.5;
            kept = -1;
        }
        if (fabs(x - previous) <= RTOL * fabs(x))
            break;
    }
    *out = fabs(fa) <= fabs(fb) ? a : b;
    return OK;
}

/* Python's math.ulp */
static double py_ulp(double x) {
    if (isnan(x))
        return x;
    x = fabs(x);
    if (isinf(x))
        return x;
    double x2 = nextafter(x, INFINITY);
    if (isinf(x2)) {
        x2 = nextafter(x, -INFINITY);
        return x - x2;
    }
    return x2 - x;
}

/* CrossingSearch._finish; *found = 0 is its None (step on from a). */
static int finish(Model *md, const Search *s, double a, double phi, double phi_rate, double size, double cover_end,
                  double bound_e, double bound_curv, int stuck, int *found, double *out) {
    *found = 1;
    *out = a;
    if (phi <= 0.0 || phi_rate >= 0.0)
        return OK;
    double beta = s->beta, scale;
    int status = scale_at(s, a, &scale);
    if (status)
        return status;
    double share = s->floor * scale;
    double fade = 1.0 - share;
    double margin_a = 1.0 - scale * size;
    if (margin_a <= 0.0)
        return OK;
    double width = py_max(2.0 * phi / -phi_rate, a != 0.0 ? 4.0 * py_ulp(a) : 1e-300);
    double b = a + width;
    if (cover_end < b) {
        double bd[4];
        status = bounds(md, b - a, size, bd);
        if (status)
            return status;
        bound_e = bd[1];
        bound_curv = bd[3];
        if (a + bd[0] < b) {
            *found = stuck;
            return OK;
        }
    }
    double curvature = 4.0 * beta * beta + 2.0 * scale * scale * bound_e * bound_curv;
    if (!(curvature * (b - a) <= -0.5 * phi_rate)) {
        *found = stuck;
        return OK;
    }
    double margin_b;
    status = margin(md, beta, a, share, fade, scale, b, &margin_b);
    if (status)
        return status;
    if (margin_b >= 0.0)
        return OK;
    return root_in_bracket(md, beta, a, share, fade, scale, a, margin_a, b, margin_b, out);
}

/* crossing._quadratic_step */
static inline double quadratic_step(double phi, double phi_rate, double curvature) {
    if (curvature <= 0.0)
        return phi_rate < 0.0 ? phi / -phi_rate : INFINITY;
    double root = sqrt(phi_rate * phi_rate + 2.0 * curvature * phi);
    if (phi_rate > 0.0)
        return (phi_rate + root) / curvature;
    return 2.0 * phi / (root - phi_rate);
}

typedef struct {
    double frontier, span, cover_end, bound_e, bound_curv, result;
    int has_result;
    long steps;
    double bad_a, bad_size_sq, bad_size_rate; /* ERR_STEPS / ERR_FINITE */
} State;

enum { ERR_STEPS = 3, ERR_FINITE = 4 };

/* The loop of CrossingSearch.advance. */
static int run(Model *md, const Search *s, State *st, double until) {
    double a = st->frontier, span = st->span;
    double cover_end = st->cover_end, bound_e = st->bound_e, bound_curv = st->bound_curv;
    double beta = s->beta, alpha = s->alpha, tolerance = s->tolerance, floor_ = s->floor;
    int status;
    while (!st->has_result && a <= until) {
        if (a > s->limit) {
            st->result = INFINITY;
            st->has_result = 1;
            break;
        }
        if (st->steps >= MAX_STEPS) {
            st->bad_a = a;
            return ERR_STEPS;
        }
        st->steps += 1;
        double e[6];
        status = probe(md, a, 1, e);
        if (status)
            return status;
        double size_sq = e[0] * e[0] + e[1] * e[1] + e[2] * e[2];
        double size_rate = e[0] * e[3] + e[1] * e[4] + e[2] * e[5];
        double scale;
        if (floor_ == 0.0) {
            double x = beta * a, y = exp(x);
            if (checked(x, y))
                return ERR_OVERFLOW;
            scale = y / alpha;
        } else {
            double x = -beta * a, y = exp(x);
            if (checked(x, y))
                return ERR_OVERFLOW;
            scale = 1.0 / (floor_ + alpha * y);
        }
        double s2 = scale * scale;
        double phi = 1.0 - s2 * size_sq;
        double phi_rate = -2.0 * beta * (1.0 - floor_ * scale) - 2.0 * s2 * size_rate;
        if (!(isfinite(phi) && isfinite(phi_rate))) {
            st->bad_a = a;
            st->bad_size_sq = size_sq;
            st->bad_size_rate = size_rate;
            return ERR_FINITE;
        }
        double size = sqrt(size_sq);
        if (phi <= tolerance) {
            int found;
            double result;
            status = finish(md, s, a, phi, phi_rate, size, cover_end, bound_e, bound_curv, 0, &found, &result);
            if (status)
                return status;
            if (found) {
                st->result = result;
                st->has_result = 1;
                break;
            }
        }
        double bd[4];
        status = bounds(md, span, size, bd);
        if (status)
            return status;
        double span_eff = bd[0], bound_rate = bd[2];
        bound_e = bd[1];
        bound_curv = bd[3];
        cover_end = a + span_eff;
        double lipschitz = 2.0 * beta + 2.0 * s2 * bound_e * bound_rate;
        double step = lipschitz > 0.0 ? phi / lipschitz : INFINITY;
        double curvature = 2.0 * s2 * (bound_rate * bound_rate + bound_e * bound_curv);
        if (curvature < INFINITY)
            step = py_max(step, quadratic_step(phi, phi_rate, curvature));
        if (step >= span_eff) {
            step = span_eff;
            span = span_eff * GROWTH;
        } else {
            span = py_max(step * GROWTH, 1e-300);
        }
        double nxt = a + step;
        if (nxt <= a) {
            int found;
            double result;
            status = finish(md, s, a, phi, phi_rate, size, cover_end, bound_e, bound_curv, 1, &found, &result);
            if (status)
                return status;
            st->result = result; /* stuck: _finish always answers */
            st->has_result = 1;
            break;
        }
        a = nxt;
    }
    st->frontier = a;
    st->span = span;
    st->cover_end = cover_end;
    st->bound_e = bound_e;
    st->bound_curv = bound_curv;
    return OK;
}

/* ---- Python glue ---------------------------------------------------------------------------- */

/* Attribute names of the agent (the model), interned once (PyInit__fastcore). */
enum {
    N_KIND, N_ROWS, N_U_OFFSET, N_CONTROL_NORM, N_K1, N_K2, N_K3, N_TRIGGERS, N_INFOS,
    /* receive: the agent's */
    N_HOOD, N_SLOT, N_AGENT_ID, N_DIMENSION, N_FAST, N_EDGE_TIME, N_LAST_TRIGGER, N_OFFSETS3,
    N_HEARD, N_EDGE_Y, N_EDGE_U, N_EDGE_Q, N_U, N_CAPACITY,
    N_LAST_EVENT, N_SEARCH, N_RESULT,
    /* receive: the TriggerInfo's */
    N_SENDER, N_RECEIVER, N_STAMP, N_CONTROL, N_REL_POSITION, N_REL_VELOCITY,
    /* trigger: the agent's and the SensedState's */
    N_AGENT, N_NEIGHBOUR_IDS, N_REL_POSITIONS, N_REL_VELOCITIES, N_SPEED_SCALE, N_SENSED_Q, N_OFFSET, N_INTERVAL,
    /* the engine's team (Team, Agenda's planning): the agent's and its threshold's */
    N_SAFETY, N_EVERYONE_HEARD, N_THRESHOLD, N_ALPHA, N_BETA, N_FLOOR, N_TOLERANCE, N_RECEIVE,
    N_NAMES
};
static const char *NAME_TEXT[N_NAMES] = {
    "_kind", "_rows", "_u_offset", "_control_norm", "k1", "k2", "k3", "triggers", "infos_received",
    "_hood", "slot", "agent_id", "dimension", "_fast", "_edge_time", "last_trigger", "_offsets3",
    "_heard", "_edge_y", "_edge_u", "_edge_q", "_u", "_capacity",
    "last_event", "_search", "result",
    "sender", "receiver", "stamp", "control", "rel_position", "rel_velocity",
    "agent", "neighbour_ids", "rel_positions", "rel_velocities", "speed_scale", "_sensed_q", "_offset", "_interval",
    "_safety", "_everyone_heard", "_threshold", "alpha", "beta", "floor", "tolerance", "receive",
};
static PyObject *NAMES[N_NAMES];
static PyObject *RAISER = NULL; /* compiled._raise(model, problem): raises the Python path's error */
/* What trigger builds its output with (configure): np.array, TriggerOutput, TriggerInfo, their keywords. */
static PyObject *NP_ARRAY = NULL, *TRIGGER_OUTPUT = NULL, *TRIGGER_INFO = NULL, *INFO_NAMES = NULL,
                *OUTPUT_NAMES = NULL;
static int DIRECT_INFO = 0, DIRECT_OUTPUT = 0; /* plain frozen slots dataclasses (compiled.plain_record) */

static int get_double(PyObject *obj, int name, double *out) {
    PyObject *value = PyObject_GetAttr(obj, NAMES[name]);
    if (value == NULL)
        return -1;
    *out = PyFloat_AsDouble(value);
    Py_DECREF(value);
    return (*out == -1.0 && PyErr_Occurred()) ? -1 : 0;
}

static int get_long(PyObject *obj, int name, long *out) {
    PyObject *value = PyObject_GetAttr(obj, NAMES[name]);
    if (value == NULL)
        return -1;
    *out = PyLong_AsLong(value);
    Py_DECREF(value);
    return (*out == -1 && PyErr_Occurred()) ? -1 : 0;
}

/* A sequence of `count` floats into out. */
static int read_floats(PyObject *seq, double *out, Py_ssize_t count, const char *what) {
    PyObject *fast = PySequence_Fast(seq, what);
    if (fast == NULL)
        return -1;
    if (PySequence_Fast_GET_SIZE(fast) != count) {
        PyErr_Format(PyExc_ValueError, "%s: %zd values, expected %zd", what, PySequence_Fast_GET_SIZE(fast),
                     count);
        Py_DECREF(fast);
        return -1;
    }
    PyObject **items = PySequence_Fast_ITEMS(fast);
    for (Py_ssize_t i = 0; i < count; i++) {
        double v = PyFloat_AsDouble(items[i]);
        if (v == -1.0 && PyErr_Occurred()) {
            Py_DECREF(fast);
            return -1;
        }
        out[i] = v;
    }
    Py_DECREF(fast);
    return 0;
}

static PyObject *configure(PyObject *self, PyObject *args, PyObject *kwargs) {
    (void)self;
    static char *names[] = {"growth", "max_steps", "rtol", "gap_fraction", "series_limit", "series", "raiser",
                            "array", "trigger_output", "trigger_info", "direct_output", "direct_info", NULL};
    PyObject *coefficients, *raiser, *array = NULL, *output = NULL, *info = NULL;
    int direct_output, direct_info;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "$dlddd" "OO" "OOO" "pp", names, &GROWTH, &MAX_STEPS, &RTOL,
                                     &GAP_FRACTION, &SERIES_LIMIT, &coefficients, &raiser, &array, &output, &info,
                                     &direct_output, &direct_info))
        return NULL;
    if (!PyType_Check(output) || !PyType_Check(info)) {
        PyErr_SetString(PyExc_TypeError, "trigger_output and trigger_info must be types");
        return NULL;
    }
    DIRECT_OUTPUT = direct_output;
    DIRECT_INFO = direct_info;
    if (read_floats(coefficients, SERIES, N_SERIES, "series") < 0)
        return NULL;
    Py_INCREF(raiser);
    Py_XSETREF(RAISER, raiser);
    /* trigger's output: np.array, TriggerOutput(time, control, infos), TriggerInfo(sender, ...) */
    if (INFO_NAMES == NULL) {
        INFO_NAMES = Py_BuildValue("(ssssss)", "sender", "receiver", "stamp", "control", "rel_position",
                                   "rel_velocity");
        OUTPUT_NAMES = Py_BuildValue("(sss)", "time", "control", "infos");
        if (INFO_NAMES == NULL || OUTPUT_NAMES == NULL)
            return NULL;
    }
    Py_XSETREF(NP_ARRAY, Py_NewRef(array));
    Py_XSETREF(TRIGGER_OUTPUT, Py_NewRef(output));
    Py_XSETREF(TRIGGER_INFO, Py_NewRef(info));
    configured = 1;
    Py_RETURN_NONE;
}

/* The model (the agent) as the loop reads it: its kind, gains, the command's offset and its
 * rows, packed into md (md->rows allocated here, freed by the caller with PyMem_Free). */
static int read_model(PyObject *model, Model *md) {
    long kind;
    if (get_long(model, N_KIND, &kind) < 0)
        return -1;
    if (kind != 1 && kind != 2) {
        PyErr_Format(PyExc_ValueError, "_kind must be 1 (ETA-1) or 2 (ETA-2), got %ld", kind);
        return -1;
    }
    md->kind = (int)kind;
    PyObject *offset = PyObject_GetAttr(model, NAMES[N_U_OFFSET]);
    if (offset == NULL)
        return -1;
    int rc = read_floats(offset, md->u_off, 3, "_u_offset");
    Py_DECREF(offset);
    if (rc < 0 || get_double(model, N_CONTROL_NORM, &md->control_norm) < 0)
        return -1;
    if (md->kind == 2 &&
        (get_double(model, N_K1, &md->k1) < 0 || get_double(model, N_K2, &md->k2) < 0 ||
         get_double(model, N_K3, &md->k3) < 0))
        return -1;
    PyObject *rows = PyObject_GetAttr(model, NAMES[N_ROWS]);
    if (rows == NULL)
        return -1;
    PyObject *fast = PySequence_Fast(rows, "_rows");
    Py_DECREF(rows);
    if (fast == NULL)
        return -1;
    md->m = PySequence_Fast_GET_SIZE(fast);
    Py_ssize_t width = md->kind == 1 ? WIDTH1 : WIDTH2;
    Py_ssize_t n = md->m > 0 ? md->m : 1;
    md->rows = PyMem_Malloc(sizeof(double) * (size_t)(n * (width + 5)));
    if (md->rows == NULL) {
        Py_DECREF(fast);
        PyErr_NoMemory();
        return -1;
    }
    md->probe = md->rows + n * width;
    md->speeds = md->probe + 4 * n;
    for (Py_ssize_t k = 0; k < md->m; k++) {
        if (read_floats(PySequence_Fast_GET_ITEM(fast, k), md->rows + k * width, width, "_rows") < 0) {
            Py_DECREF(fast);
            return -1;
        }
    }
    Py_DECREF(fast);
    return 0;
}

/* The error the pure-Python path raises with a message: compiled._raise(model, problem) raises it. */
static void raise_problem(PyObject *model, PyObject *problem) {
    if (problem == NULL)
        return;
    PyObject *out = PyObject_CallFunctionObjArgs(RAISER, model, problem, NULL);
    Py_DECREF(problem);
    if (out != NULL) { /* the raiser must raise */
        Py_DECREF(out);
        PyErr_SetString(PyExc_RuntimeError, "compiled._raise returned instead of raising");
    }
}

/* ---- Search: CrossingSearch of a plain-float agent, its state and packed rows in C ---------- */

typedef struct {
    PyObject_HEAD
    PyObject *model;
    Model md;                 /* md.rows == NULL until the first advance reads the model */
    long known_triggers;      /* the model's knowledge when md was read: (triggers, infos_received) */
    long known_infos;
    Search s;
    State st;
    double start;
    PyObject *team;      /* the engine's Team whose ledger it was made from (Agenda.link), or NULL */
    Py_ssize_t team_pos; /* its agent's position there */
} SearchObject;

/* The team's ledger of agent a, while the team owns the agent's knowledge (Team): its counters (1), or 0
 * (the agent's attributes are its knowledge); ledger_model packs it as read_model packs the agent. */
static int ledger_counters(PyObject *team, Py_ssize_t a, long *triggers, long *infos);
static int ledger_model(PyObject *team, Py_ssize_t a, Model *md);

/* The packed model, read again when the agent's knowledge changed since it was read (as the
 * Python path, which reads the agent's rows at every evaluation): from the team's ledger while the team
 * owns the agent's knowledge, else from the agent. */
static int search_model(SearchObject *self) {
    long triggers, infos;
    int owned = self->team != NULL && ledger_counters(self->team, self->team_pos, &triggers, &infos);
    if (!owned &&
        (get_long(self->model, N_TRIGGERS, &triggers) < 0 || get_long(self->model, N_INFOS, &infos) < 0))
        return -1;
    if (self->md.rows != NULL && triggers == self->known_triggers && infos == self->known_infos)
        return 0;
    PyMem_Free(self->md.rows);
    memset(&self->md, 0, sizeof self->md);
    if ((owned ? ledger_model(self->team, self->team_pos, &self->md) : read_model(self->model, &self->md)) < 0) {
        PyMem_Free(self->md.rows);
        self->md.rows = NULL;
        return -1;
    }
    self->known_triggers = triggers;
    self->known_infos = infos;
    return 0;
}

static PyObject *search_new(PyTypeObject *type, PyObject *args, PyObject *kwargs) {
    static char *names[] = {"model", "start", "alpha", "beta", "limit", "tolerance", "initial_step", "floor", NULL};
    PyObject *model;
    double start, alpha, beta, limit, tolerance, initial_step, floor_;
    if (!configured) {
        PyErr_SetString(PyExc_RuntimeError, "_fastcore.configure was not called");
        return NULL;
    }
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O$ddddddd", names, &model, &start, &alpha, &beta, &limit,
                                     &tolerance, &initial_step, &floor_))
        return NULL;
    SearchObject *self = (SearchObject *)type->tp_alloc(type, 0);
    if (self == NULL)
        return NULL;
    self->model = Py_NewRef(model);
    self->start = start;
    self->s = (Search){.alpha = alpha, .beta = beta, .floor = floor_, .limit = limit, .tolerance = tolerance};
    /* CrossingSearch.__init__: at the start, no result, no step, the first span, no last step. */
    self->st.frontier = start;
    self->st.span = initial_step;
    self->st.cover_end = -INFINITY;
    self->st.bound_e = NAN;
    self->st.bound_curv = NAN;
    return (PyObject *)self;
}

static int search_traverse(SearchObject *self, visitproc visit, void *arg) {
    Py_VISIT(self->model);
    Py_VISIT(self->team);
    return 0;
}

static int search_clear(SearchObject *self) {
    Py_CLEAR(self->model);
    Py_CLEAR(self->team);
    return 0;
}

static void search_dealloc(SearchObject *self) {
    PyObject_GC_UnTrack(self);
    search_clear(self);
    PyMem_Free(self->md.rows);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyObject *search_result(SearchObject *self, void *closure) {
    (void)closure;
    return self->st.has_result ? PyFloat_FromDouble(self->st.result) : Py_NewRef(Py_None);
}

/* advance(until): CrossingSearch.advance; its result (None: not done yet). Errors are the Python
 * path's: the failing step counted, the frontier left where it was. */
static PyObject *search_step(SearchObject *self, double until) {
    State *st = &self->st;
    if (!st->has_result && st->frontier <= until) { /* else the loop would not take a step */
        if (self->model == NULL) {
            PyErr_SetString(PyExc_RuntimeError, "search without a model");
            return NULL;
        }
        if (search_model(self) < 0)
            return NULL;
        switch (run(&self->md, &self->s, st, until)) {
        case OK:
            break;
        case ERR_OVERFLOW:
            PyErr_SetString(PyExc_OverflowError, "math range error");
            return NULL;
        case ERR_RANGE:
            raise_problem(self->model, Py_BuildValue("(sndd)", "range", self->md.bad_k, self->md.bad_r,
                                                     self->md.bad_c));
            return NULL;
        case ERR_STEPS:
            raise_problem(self->model, Py_BuildValue("(sd)", "steps", st->bad_a));
            return NULL;
        default:
            raise_problem(self->model,
                          Py_BuildValue("(sddd)", "finite", st->bad_a, st->bad_size_sq, st->bad_size_rate));
            return NULL;
        }
    }
    return search_result(self, NULL);
}

static PyObject *search_advance(SearchObject *self, PyObject *arg) {
    double until = PyFloat_AsDouble(arg);
    if (until == -1.0 && PyErr_Occurred())
        return NULL;
    return search_step(self, until);
}

static PyObject *search_run(SearchObject *self, PyObject *unused) {
    (void)unused;
    return search_step(self, INFINITY);
}

static PyObject *search_done(SearchObject *self, void *closure) {
    (void)closure;
    return PyBool_FromLong(self->st.has_result);
}

static PyObject *search_cover(SearchObject *self, void *closure) {
    (void)closure;
    return Py_BuildValue("(ddd)", self->st.cover_end, self->st.bound_e, self->st.bound_curv);
}

static PyMemberDef search_members[] = {
    {"model", T_OBJECT, offsetof(SearchObject, model), READONLY, "the agent whose error is searched"},
    {"start", T_DOUBLE, offsetof(SearchObject, start), READONLY, "where the search began"},
    {"alpha", T_DOUBLE, offsetof(SearchObject, s.alpha), READONLY, "α of the threshold c0 + α e^{-βt}"},
    {"beta", T_DOUBLE, offsetof(SearchObject, s.beta), READONLY, "β of the threshold"},
    {"floor", T_DOUBLE, offsetof(SearchObject, s.floor), READONLY, "c0 of the threshold"},
    {"limit", T_DOUBLE, offsetof(SearchObject, s.limit), READONLY, "no crossing searched past this time"},
    {"tolerance", T_DOUBLE, offsetof(SearchObject, s.tolerance), READONLY, "the margin that counts as reached"},
    {"frontier", T_DOUBLE, offsetof(SearchObject, st.frontier), READONLY,
     "the next point examined; no crossing in [start, frontier)"},
    {"steps", T_LONG, offsetof(SearchObject, st.steps), READONLY, "certified steps taken"},
    {"_span", T_DOUBLE, offsetof(SearchObject, st.span), READONLY, "the next trial span"},
    {NULL, 0, 0, 0, NULL},
};

static PyGetSetDef search_getset[] = {
    {"result", (getter)search_result, NULL, "None until done, then the crossing time (inf: none up to limit)",
     NULL},
    {"done", (getter)search_done, NULL, "True once the result is known", NULL},
    {"_cover", (getter)search_cover, NULL, "(end, E, E2): the last step's bounds", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyMethodDef search_methods[] = {
    {"advance", (PyCFunction)search_advance, METH_O,
     "advance(until): certified steps while the frontier is <= until; the result (None: not done yet)."},
    {"run", (PyCFunction)search_run, METH_NOARGS, "run(): search to the end; the crossing time, or inf."},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject SearchType = {
    PyVarObject_HEAD_INIT(NULL, 0).tp_name = "formation_agent.core._fastcore.Search",
    .tp_doc = "Search(model, *, start, alpha, beta, limit, tolerance, initial_step, floor): "
              "crossing.CrossingSearch of a plain-float agent (p <= 3), compiled; the same floats.",
    .tp_basicsize = sizeof(SearchObject),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC,
    .tp_new = search_new,
    .tp_dealloc = (destructor)search_dealloc,
    .tp_traverse = (traverseproc)search_traverse,
    .tp_clear = (inquiry)search_clear,
    .tp_members = search_members,
    .tp_getset = search_getset,
    .tp_methods = search_methods,
};

/* ---- receive: _EventTriggeredAgent.receive of a plain-float agent --------------------------- */

/* Owned references, released together. */
typedef struct {
    PyObject *items[48];
    int n;
} Held;

static PyObject *hold(Held *h, PyObject *obj) {
    if (obj != NULL)
        h->items[h->n++] = obj;
    return obj;
}

static void release(Held *h) {
    while (h->n > 0)
        Py_DECREF(h->items[--h->n]);
}

/* `value` as p finite floats when it is a tuple or list of p floats or ints (Neighbourhood.floats
 * accepts these with the same values); 0 otherwise, without an error set: the Python path decides. */
static int plain_floats(PyObject *value, Py_ssize_t p, double *out) {
    if (!(PyTuple_CheckExact(value) || PyList_CheckExact(value)) || PySequence_Fast_GET_SIZE(value) != p)
        return 0;
    PyObject **items = PySequence_Fast_ITEMS(value);
    for (Py_ssize_t i = 0; i < p; i++) {
        if (!(PyFloat_Check(items[i]) || PyLong_Check(items[i])))
            return 0;
        double v = PyFloat_AsDouble(items[i]);
        if (v == -1.0 && PyErr_Occurred()) {
            PyErr_Clear();
            return 0;
        }
        if (!isfinite(v))
            return 0;
        out[i] = v;
    }
    return 1;
}

/* A number (float or int) as a double; 0 without an error set otherwise. */
static int plain_double(PyObject *value, double *out) {
    if (!(PyFloat_Check(value) || PyLong_Check(value)))
        return 0;
    *out = PyFloat_AsDouble(value);
    if (*out == -1.0 && PyErr_Occurred()) {
        PyErr_Clear();
        return 0;
    }
    return 1;
}

static PyObject *ZERO = NULL; /* the float +0.0, shared (as the Python path shares its padding's 0.0) */

/* A float object of v: the shared +0.0, or a new one. */
static inline PyObject *float_object(double v) {
    if (v == 0.0 && !signbit(v))
        return Py_NewRef(ZERO);
    return PyFloat_FromDouble(v);
}

static PyObject *floats_tuple(const double *v, Py_ssize_t n) {
    PyObject *t = PyTuple_New(n);
    if (t == NULL)
        return NULL;
    for (Py_ssize_t i = 0; i < n; i++) {
        PyObject *x = float_object(v[i]);
        if (x == NULL) {
            Py_DECREF(t);
            return NULL;
        }
        PyTuple_SET_ITEM(t, i, x);
    }
    /* A tuple of floats cannot be part of a reference cycle: untracked now, as the garbage collector
     * would untrack it at its first pass (_PyTuple_MaybeUntrack), so the knowledge an agent keeps
     * between messages is not traversed, nor promoted to the old generations. */
    PyObject_GC_UnTrack(t);
    return t;
}

/* list[k] = value (a new reference, stolen); -1 on error. */
static int list_put(PyObject *list, Py_ssize_t k, PyObject *value) {
    if (value == NULL)
        return -1;
    if (!PyList_CheckExact(list) || k >= PyList_GET_SIZE(list)) {
        Py_DECREF(value);
        PyErr_SetString(PyExc_TypeError, "receive: the agent's edge lists are not lists of its edges");
        return -1;
    }
    PyList_SetItem(list, k, value);
    return 0;
}

/* A frozen slots dataclass of `names`, built as its __init__ builds it (object.__setattr__ of each
 * field) where configure found it a plain one (DIRECT), else by calling it. */
static PyObject *make_record(PyObject *type, int direct, PyObject *names, PyObject *const *values) {
    Py_ssize_t n = PyTuple_GET_SIZE(names);
    if (!direct)
        return PyObject_Vectorcall(type, values, 0, names);
    PyObject *obj = ((PyTypeObject *)type)->tp_alloc((PyTypeObject *)type, 0);
    for (Py_ssize_t i = 0; obj != NULL && i < n; i++)
        if (PyObject_GenericSetAttr(obj, PyTuple_GET_ITEM(names, i), values[i]) < 0)
            Py_CLEAR(obj);
    return obj;
}

/* The message read and checked as the Python path checks it; 0: leave it to the Python path. */
typedef struct {
    Py_ssize_t k, p;
    int kind;
    double stamp, rel[3], control[3], velocity[3];
} Message;

static int read_message(PyObject *agent, PyObject *info, Held *h, Message *msg) {
    PyObject *hood = hold(h, PyObject_GetAttr(agent, NAMES[N_HOOD]));
    PyObject *agent_id = hood ? hold(h, PyObject_GetAttr(agent, NAMES[N_AGENT_ID])) : NULL;
    PyObject *receiver = agent_id ? hold(h, PyObject_GetAttr(info, NAMES[N_RECEIVER])) : NULL;
    PyObject *sender = receiver ? hold(h, PyObject_GetAttr(info, NAMES[N_SENDER])) : NULL;
    PyObject *slot = sender ? hold(h, PyObject_GetAttr(hood, NAMES[N_SLOT])) : NULL;
    if (slot == NULL || !PyDict_CheckExact(slot))
        return -1;
    int same = PyObject_RichCompareBool(receiver, agent_id, Py_EQ);
    if (same <= 0) /* an error: the Python path raises it, or its own */
        return same < 0 ? (PyErr_Clear(), 0) : 0;
    PyObject *k = PyDict_GetItemWithError(slot, sender);
    if (k == NULL)
        return PyErr_Occurred() ? (PyErr_Clear(), 0) : 0;
    msg->k = PyLong_AsSsize_t(k);
    long kind, p, fast;
    if (msg->k < 0 || get_long(agent, N_KIND, &kind) < 0 || get_long(agent, N_DIMENSION, &p) < 0 ||
        get_long(agent, N_FAST, &fast) < 0)
        return -1;
    if (!fast || p < 1 || p > 3 || (kind != 1 && kind != 2))
        return 0;
    msg->kind = (int)kind;
    msg->p = p;
    PyObject *stamp = hold(h, PyObject_GetAttr(info, NAMES[N_STAMP]));
    PyObject *edge_time = stamp ? hold(h, PyObject_GetAttr(agent, NAMES[N_EDGE_TIME])) : NULL;
    PyObject *last_trigger = edge_time ? hold(h, PyObject_GetAttr(agent, NAMES[N_LAST_TRIGGER])) : NULL;
    if (last_trigger == NULL)
        return -1;
    if (!plain_double(stamp, &msg->stamp) || !isfinite(msg->stamp) || !PyList_CheckExact(edge_time) ||
        msg->k >= PyList_GET_SIZE(edge_time))
        return 0;
    double edge, last = -INFINITY;
    if (!plain_double(PyList_GET_ITEM(edge_time, msg->k), &edge) ||
        (last_trigger != Py_None && !plain_double(last_trigger, &last)))
        return 0;
    if (msg->stamp < edge || (last_trigger != Py_None && msg->stamp < last))
        return 0; /* back in time: the Python path raises */
    PyObject *rel = hold(h, PyObject_GetAttr(info, NAMES[N_REL_POSITION]));
    PyObject *control = rel ? hold(h, PyObject_GetAttr(info, NAMES[N_CONTROL])) : NULL;
    PyObject *velocity = control ? hold(h, PyObject_GetAttr(info, NAMES[N_REL_VELOCITY])) : NULL;
    if (velocity == NULL)
        return -1;
    if (!plain_floats(rel, p, msg->rel) || !plain_floats(control, p, msg->control))
        return 0;
    if (kind == 2 && (velocity == Py_None || !plain_floats(velocity, p, msg->velocity)))
        return 0;
    return 1;
}

/* The row of edge k (Eta1Agent._row, Eta2Agent._row), laid out as WIDTH1 / WIDTH2, from its anchor time, its
 * edge state y (ETA-2: and q), the agent's command u, the neighbour's uj and the capacity c; returns the width.
 * The one place the four paths that write a row (the attributes' and the ledger's trigger and receive) take
 * it from, so their floats cannot part. */
static Py_ssize_t fill_row(double *row, int kind, double anchor, const double *y, const double *q, const double *u,
                           const double *uj, double c) {
    row[0] = anchor;
    row[1] = y[0];
    row[2] = y[1];
    row[3] = y[2];
    if (kind == 1) { /* Eta1Agent._row */
        double v0 = u[0] - uj[0], v1 = u[1] - uj[1], v2 = u[2] - uj[2];
        row[4] = v0;
        row[5] = v1;
        row[6] = v2;
        row[7] = sqrt(v0 * v0 + v1 * v1 + v2 * v2);
        row[8] = c;
        return WIDTH1;
    }
    row[4] = q[0]; /* Eta2Agent._row */
    row[5] = q[1];
    row[6] = q[2];
    row[7] = u[0] - uj[0];
    row[8] = u[1] - uj[1];
    row[9] = u[2] - uj[2];
    row[10] = c;
    return WIDTH2;
}

/* The agent's knowledge updated as the Python path updates it (the same floats). */
static int take_message(PyObject *agent, Held *h, const Message *msg) {
    Py_ssize_t k = msg->k, p = msg->p;
    double d[3], y[3] = {0.0, 0.0, 0.0}, uj[3] = {0.0, 0.0, 0.0}, q[3] = {0.0, 0.0, 0.0}, u[3], c;
    PyObject *offsets = hold(h, PyObject_GetAttr(agent, NAMES[N_OFFSETS3]));
    PyObject *own = offsets ? hold(h, PyObject_GetAttr(agent, NAMES[N_U])) : NULL;
    PyObject *capacity = own ? hold(h, PyObject_GetAttr(agent, NAMES[N_CAPACITY])) : NULL;
    if (capacity == NULL)
        return -1;
    PyObject *offset = PySequence_GetItem(offsets, k), *cap = PySequence_GetItem(capacity, k);
    hold(h, offset);
    hold(h, cap);
    if (offset == NULL || cap == NULL || read_floats(offset, d, 3, "_offsets3") < 0 ||
        read_floats(own, u, 3, "_u") < 0 || (c = PyFloat_AsDouble(cap), c == -1.0 && PyErr_Occurred()))
        return -1;
    for (Py_ssize_t i = 0; i < p; i++) {
        y[i] = -msg->rel[i] - d[i]; /* the message carries x_j - x_i; the edge state is x_i - x_j - d_ij */
        uj[i] = msg->control[i];
        q[i] = -msg->velocity[i];
    }
    PyObject *heard = hold(h, PyObject_GetAttr(agent, NAMES[N_HEARD]));
    PyObject *edge_time = heard ? hold(h, PyObject_GetAttr(agent, NAMES[N_EDGE_TIME])) : NULL;
    PyObject *edge_y = edge_time ? hold(h, PyObject_GetAttr(agent, NAMES[N_EDGE_Y])) : NULL;
    PyObject *edge_u = edge_y ? hold(h, PyObject_GetAttr(agent, NAMES[N_EDGE_U])) : NULL;
    PyObject *rows = edge_u ? hold(h, PyObject_GetAttr(agent, NAMES[N_ROWS])) : NULL;
    if (rows == NULL)
        return -1;
    if (msg->kind == 2) { /* Eta2Agent._receive_extra */
        PyObject *edge_q = hold(h, PyObject_GetAttr(agent, NAMES[N_EDGE_Q]));
        if (edge_q == NULL || list_put(edge_q, k, floats_tuple(q, 3)) < 0)
            return -1;
    }
    if (list_put(heard, k, Py_NewRef(Py_True)) < 0 ||
        list_put(edge_time, k, PyFloat_FromDouble(msg->stamp)) < 0 || list_put(edge_y, k, floats_tuple(y, 3)) < 0 ||
        list_put(edge_u, k, floats_tuple(uj, 3)) < 0)
        return -1;
    double row[WIDTH2];
    Py_ssize_t width = fill_row(row, msg->kind, msg->stamp, y, q, u, uj, c);
    return list_put(rows, k, floats_tuple(row, width));
}

/* The counters, the last event, and the plan dropped unless it is due at or before the message. */
static int after_message(PyObject *agent, Held *h, double stamp) {
    long infos;
    double last;
    PyObject *last_event = hold(h, PyObject_GetAttr(agent, NAMES[N_LAST_EVENT]));
    if (last_event == NULL || get_long(agent, N_INFOS, &infos) < 0)
        return -1;
    PyObject *count = PyLong_FromLong(infos + 1);
    if (count == NULL || PyObject_SetAttr(agent, NAMES[N_INFOS], count) < 0) {
        Py_XDECREF(count);
        return -1;
    }
    Py_DECREF(count);
    last = PyFloat_AsDouble(last_event);
    if (last == -1.0 && PyErr_Occurred())
        return -1;
    if (stamp > last) { /* max(self.last_event, stamp) */
        PyObject *now = PyFloat_FromDouble(stamp);
        int rc = now == NULL ? -1 : PyObject_SetAttr(agent, NAMES[N_LAST_EVENT], now);
        Py_XDECREF(now);
        if (rc < 0)
            return -1;
    }
    PyObject *search = hold(h, PyObject_GetAttr(agent, NAMES[N_SEARCH]));
    if (search == NULL)
        return -1;
    if (search != Py_None) {
        PyObject *result = hold(h, PyObject_GetAttr(search, NAMES[N_RESULT]));
        if (result == NULL)
            return -1;
        if (result != Py_None) {
            double due = PyFloat_AsDouble(result);
            if (due == -1.0 && PyErr_Occurred())
                return -1;
            if (due <= stamp)
                return 0; /* already due at or before this time: its own trigger re-plans everything */
        }
    }
    return PyObject_SetAttr(agent, NAMES[N_SEARCH], Py_None);
}

/* receive(agent, info): _EventTriggeredAgent.receive for a plain-float agent (p <= 3), the same
 * updates and floats. False, with nothing changed, where a check fails or the message is not made
 * of plain tuples and floats: the Python path then takes it (and raises its error). */
static PyObject *receive(PyObject *self, PyObject *args) {
    (void)self;
    PyObject *agent, *info;
    if (!PyArg_ParseTuple(args, "OO", &agent, &info))
        return NULL;
    Held h = {.n = 0};
    Message msg;
    int status = read_message(agent, info, &h, &msg);
    if (status == 1)
        status = take_message(agent, &h, &msg) < 0 || after_message(agent, &h, msg.stamp) < 0 ? -1 : 1;
    release(&h);
    if (status < 0)
        return NULL;
    return PyBool_FromLong(status);
}

/* ---- trigger: _EventTriggeredAgent.trigger of a plain-float agent without the safety layer --- */

#define MAX_EDGES 64

/* What a trigger is handed, read and checked as the Python path checks it. */
typedef struct {
    Py_ssize_t m, p;
    int kind;
    double t;
    double rel[MAX_EDGES][3], extra[MAX_EDGES][3], y[MAX_EDGES][3], length[MAX_EDGES];
} Sensing;

/* One vector of p finite floats per neighbour (Neighbourhood.rows): 0 where the Python path decides. */
static int sensed_rows(PyObject *values, PyObject *ids, Sensing *in, double (*out)[3]) {
    if (values == NULL || !PyDict_CheckExact(values) || PyDict_GET_SIZE(values) != in->m)
        return 0;
    for (Py_ssize_t k = 0; k < in->m; k++) {
        PyObject *row = PyDict_GetItemWithError(values, PyTuple_GET_ITEM(ids, k));
        if (row == NULL)
            return PyErr_Occurred() ? (PyErr_Clear(), 0) : 0;
        if (!plain_floats(row, in->p, out[k]))
            return 0;
        for (Py_ssize_t i = in->p; i < 3; i++)
            out[k][i] = 0.0; /* padded to three components */
    }
    return 1;
}

static int read_sensing(PyObject *agent, PyObject *t_obj, PyObject *sensed, Held *h, Sensing *in) {
    long kind, p, fast;
    if (get_long(agent, N_KIND, &kind) < 0 || get_long(agent, N_DIMENSION, &p) < 0 ||
        get_long(agent, N_FAST, &fast) < 0)
        return -1;
    if (!fast || p < 1 || p > 3 || (kind != 1 && kind != 2) || !plain_double(t_obj, &in->t) || !isfinite(in->t))
        return 0;
    in->kind = (int)kind;
    in->p = p;
    PyObject *agent_id = hold(h, PyObject_GetAttr(agent, NAMES[N_AGENT_ID]));
    PyObject *who = agent_id ? hold(h, PyObject_GetAttr(sensed, NAMES[N_AGENT])) : NULL;
    PyObject *ids = who ? hold(h, PyObject_GetAttr(agent, NAMES[N_NEIGHBOUR_IDS])) : NULL;
    PyObject *last_trigger = ids ? hold(h, PyObject_GetAttr(agent, NAMES[N_LAST_TRIGGER])) : NULL;
    PyObject *offsets = last_trigger ? hold(h, PyObject_GetAttr(agent, NAMES[N_OFFSETS3])) : NULL;
    PyObject *capacity = offsets ? hold(h, PyObject_GetAttr(agent, NAMES[N_CAPACITY])) : NULL;
    if (capacity == NULL)
        return -1;
    int same = PyObject_RichCompareBool(who, agent_id, Py_EQ);
    if (same <= 0)
        return same < 0 ? (PyErr_Clear(), 0) : 0;
    double last;
    if (last_trigger != Py_None && (!plain_double(last_trigger, &last) || in->t < last))
        return 0;
    if (!PyTuple_CheckExact(ids) || PyTuple_GET_SIZE(ids) > MAX_EDGES || !PyList_CheckExact(offsets) ||
        !PyList_CheckExact(capacity))
        return 0;
    in->m = PyTuple_GET_SIZE(ids);
    PyObject *rel = hold(h, PyObject_GetAttr(sensed, NAMES[N_REL_POSITIONS]));
    if (rel == NULL)
        return -1;
    if (!sensed_rows(rel, ids, in, in->rel))
        return 0;
    for (Py_ssize_t k = 0; k < in->m; k++) {
        double d[3], c;
        if (read_floats(PyList_GET_ITEM(offsets, k), d, 3, "_offsets3") < 0)
            return -1;
        if (!plain_double(PyList_GET_ITEM(capacity, k), &c))
            return 0;
        double sum = 0.0;
        for (Py_ssize_t i = 0; i < 3; i++)
            in->y[k][i] = 0.0;
        for (Py_ssize_t i = 0; i < p; i++) {
            in->y[k][i] = in->rel[k][i] - d[i]; /* y_ij = x_i - x_j - d_ij */
            sum += in->y[k][i] * in->y[k][i];   /* sum(v * v for v in row): from 0, left to right */
        }
        in->length[k] = sqrt(sum);
        if (in->length[k] >= c)
            return 0; /* out of its range: the Python path raises */
    }
    if (kind == 2) {
        PyObject *vel = hold(h, PyObject_GetAttr(sensed, NAMES[N_REL_VELOCITIES]));
        if (vel == NULL)
            return -1;
        if (!sensed_rows(vel, ids, in, in->extra))
            return 0;
    }
    return 1;
}

/* [t] * m, or a list of the rows as tuples of n floats. */
static PyObject *rows_list(double (*rows)[3], Py_ssize_t m, Py_ssize_t n) {
    PyObject *list = PyList_New(m);
    for (Py_ssize_t k = 0; list != NULL && k < m; k++) {
        PyObject *row = floats_tuple(rows[k], n);
        if (row == NULL)
            Py_CLEAR(list);
        else
            PyList_SET_ITEM(list, k, row);
    }
    return list;
}

static int set_attr(PyObject *obj, int name, PyObject *value) { /* value: a new reference, released */
    if (value == NULL)
        return -1;
    int rc = PyObject_SetAttr(obj, NAMES[name], value);
    Py_DECREF(value);
    return rc;
}


/* The new input (_update, _command) and the knowledge after the trigger, as the Python path. */
static int take_sensing(PyObject *agent, Held *h, Sensing *in, double *control, double *offset) {
    Py_ssize_t m = in->m, p = in->p;
    double total[3] = {0.0, 0.0, 0.0}, k1 = 0.0, k2 = 0.0;
    if (in->kind == 2 && (get_double(agent, N_K1, &k1) < 0 || get_double(agent, N_K2, &k2) < 0))
        return -1;
    PyObject *capacity = hold(h, PyObject_GetAttr(agent, NAMES[N_CAPACITY]));
    if (capacity == NULL)
        return -1;
    for (Py_ssize_t k = 0; k < m; k++) { /* _weighted_sum */
        double r = in->length[k], c = PyFloat_AsDouble(PyList_GET_ITEM(capacity, k));
        double gap = c - r;
        double w = (2.0 * c - r) / (gap * gap); /* ω_ij (fij) */
        for (Py_ssize_t i = 0; i < p; i++) {
            double v = in->kind == 1 ? in->y[k][i] : k1 * in->y[k][i] + k2 * in->extra[k][i];
            total[i] += w * v;
        }
    }
    double kappa = 1.0;
    if (in->kind == 1 && get_double(agent, N_SPEED_SCALE, &kappa) < 0)
        return -1;
    for (Py_ssize_t i = 0; i < 3; i++) {
        offset[i] = i < p ? -total[i] : 0.0; /* (uxsingle) / (uxdouble) */
        control[i] = i < p && in->kind == 1 ? kappa * offset[i] : offset[i]; /* κ u_i (ETA-1) */
    }
    PyObject *edge_u = hold(h, PyObject_GetAttr(agent, NAMES[N_EDGE_U]));
    if (edge_u == NULL || !PyList_CheckExact(edge_u) || PyList_GET_SIZE(edge_u) != m)
        return -1;
    if (in->kind == 2) { /* Eta2Agent._update */
        if (set_attr(agent, N_SENSED_Q, rows_list(in->extra, m, p)) < 0 ||
            set_attr(agent, N_EDGE_Q, rows_list(in->extra, m, 3)) < 0)
            return -1;
    }
    PyObject *command = hold(h, floats_tuple(control, p)), *own = hold(h, floats_tuple(offset, p));
    if (command == NULL || own == NULL || set_attr(agent, N_CONTROL, PyObject_CallOneArg(NP_ARRAY, command)) < 0 ||
        set_attr(agent, N_OFFSET, PyObject_CallOneArg(NP_ARRAY, own)) < 0)
        return -1;
    PyObject *rows = PyList_New(m);
    if (rows == NULL || set_attr(agent, N_ROWS, Py_NewRef(rows)) < 0) {
        Py_XDECREF(rows);
        return -1;
    }
    hold(h, rows);
    for (Py_ssize_t k = 0; k < m; k++) {
        double uj[3], row[WIDTH2], *y = in->y[k];
        if (read_floats(PyList_GET_ITEM(edge_u, k), uj, 3, "_edge_u") < 0)
            return -1;
        double c = PyFloat_AsDouble(PyList_GET_ITEM(capacity, k));
        Py_ssize_t width = fill_row(row, in->kind, in->t, y, in->extra[k], control, uj, c);
        PyObject *tuple = floats_tuple(row, width);
        if (tuple == NULL)
            return -1;
        PyList_SET_ITEM(rows, k, tuple);
    }
    double norm = sqrt(offset[0] * offset[0] + offset[1] * offset[1] + offset[2] * offset[2]);
    PyObject *edge_time = PyList_New(m); /* [t] * m */
    for (Py_ssize_t k = 0; edge_time != NULL && k < m; k++) {
        PyObject *x = PyFloat_FromDouble(in->t);
        if (x == NULL)
            Py_CLEAR(edge_time);
        else
            PyList_SET_ITEM(edge_time, k, x);
    }
    if (set_attr(agent, N_EDGE_TIME, edge_time) < 0 || set_attr(agent, N_EDGE_Y, rows_list(in->y, m, 3)) < 0 ||
        set_attr(agent, N_U, floats_tuple(control, 3)) < 0 || set_attr(agent, N_U_OFFSET, floats_tuple(offset, 3)) < 0 ||
        set_attr(agent, N_CONTROL_NORM, PyFloat_FromDouble(norm)) < 0)
        return -1;
    return 0;
}

/* The counters and times after a trigger (_interval, last_trigger, last_event, the plan dropped). */
static int after_trigger(PyObject *agent, Held *h, PyObject *t) {
    double now = PyFloat_AsDouble(t), last_event;
    long triggers;
    PyObject *last_trigger = hold(h, PyObject_GetAttr(agent, NAMES[N_LAST_TRIGGER]));
    PyObject *last = last_trigger ? hold(h, PyObject_GetAttr(agent, NAMES[N_LAST_EVENT])) : NULL;
    if (last == NULL || get_long(agent, N_TRIGGERS, &triggers) < 0)
        return -1;
    if (last_trigger != Py_None) {
        double before = PyFloat_AsDouble(last_trigger);
        if (now > before && set_attr(agent, N_INTERVAL, PyFloat_FromDouble(now - before)) < 0)
            return -1;
    }
    last_event = PyFloat_AsDouble(last);
    if (PyErr_Occurred() || PyObject_SetAttr(agent, NAMES[N_LAST_TRIGGER], t) < 0 ||
        (now > last_event && PyObject_SetAttr(agent, NAMES[N_LAST_EVENT], t) < 0) ||
        PyObject_SetAttr(agent, NAMES[N_SEARCH], Py_None) < 0 ||
        set_attr(agent, N_TRIGGERS, PyLong_FromLong(triggers + 1)) < 0)
        return -1;
    return 0;
}

/* TriggerOutput(time=t, control=np.array(control), infos=(TriggerInfo(...) per neighbour)). */
static PyObject *trigger_output(PyObject *agent, Held *h, Sensing *in, PyObject *t, const double *control) {
    PyObject *agent_id = hold(h, PyObject_GetAttr(agent, NAMES[N_AGENT_ID]));
    PyObject *ids = agent_id ? hold(h, PyObject_GetAttr(agent, NAMES[N_NEIGHBOUR_IDS])) : NULL;
    PyObject *command = ids ? hold(h, floats_tuple(control, in->p)) : NULL;
    PyObject *infos = command ? hold(h, PyTuple_New(in->m)) : NULL;
    if (infos == NULL)
        return NULL;
    for (Py_ssize_t k = 0; k < in->m; k++) {
        PyObject *rel = floats_tuple(in->rel[k], in->p);
        PyObject *velocity = in->kind == 1 ? Py_NewRef(Py_None) : floats_tuple(in->extra[k], in->p);
        PyObject *info = NULL;
        if (rel != NULL && velocity != NULL) {
            PyObject *args[6] = {agent_id, PyTuple_GET_ITEM(ids, k), t, command, rel, velocity};
            info = make_record(TRIGGER_INFO, DIRECT_INFO, INFO_NAMES, args);
        }
        Py_XDECREF(rel);
        Py_XDECREF(velocity);
        if (info == NULL)
            return NULL;
        PyTuple_SET_ITEM(infos, k, info);
    }
    PyObject *array = hold(h, PyObject_CallOneArg(NP_ARRAY, command));
    if (array == NULL)
        return NULL;
    PyObject *args[3] = {t, array, infos};
    return make_record(TRIGGER_OUTPUT, DIRECT_OUTPUT, OUTPUT_NAMES, args);
}

/* trigger(agent, t, sensed): _EventTriggeredAgent.trigger for a plain-float agent (p <= 3) without
 * the safety layer, the same updates, floats and output. None, with nothing changed, where a check
 * fails or the sensing is not made of plain tuples and floats: the Python path then takes it. */
static PyObject *trigger(PyObject *self, PyObject *args) {
    (void)self;
    PyObject *agent, *t_obj, *sensed;
    if (!PyArg_ParseTuple(args, "OOO", &agent, &t_obj, &sensed))
        return NULL;
    if (TRIGGER_OUTPUT == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "_fastcore.configure was not given the trigger's types");
        return NULL;
    }
    Held h = {.n = 0};
    Sensing *in = PyMem_Malloc(sizeof(Sensing));
    if (in == NULL)
        return PyErr_NoMemory();
    PyObject *out = NULL;
    int status = read_sensing(agent, t_obj, sensed, &h, in);
    if (status == 0)
        out = Py_NewRef(Py_None);
    else if (status == 1) {
        double control[3], offset[3];
        PyObject *t = hold(&h, PyFloat_FromDouble(in->t));
        if (t != NULL && take_sensing(agent, &h, in, control, offset) == 0 &&
            after_trigger(agent, &h, t) == 0)
            out = trigger_output(agent, &h, in, t, control);
    }
    release(&h);
    PyMem_Free(in);
    return out;
}


/* ---- the team's ledger: each agent's knowledge in C while the engine runs ---------------------- */

/* Edge k of an agent as its knowledge holds it (eta.py's lists, element k): _offsets3, _capacity (fixed),
 * _heard, _edge_time, _edge_y, _edge_u, ETA-2's _edge_q and _sensed_q, and its packed row (_rows). */
typedef struct {
    double d[3], c;
    double time, y[3], u[3], q[3], sensed_q[3];
    double row[WIDTH2]; /* _row(k), laid out as WIDTH1 / WIDTH2 */
    char heard, row_set; /* row_set 0: _rows[k] is () (no trigger and no message on the edge yet) */
} Edge;

/* An agent's knowledge as the team holds it (Team): what trigger and receive write of the agent (its
 * edges in the team's Edge array), and what a search and the threshold read of it (fixed). While `own`, the
 * ledger is the agent's knowledge and its Python attributes are as the team last wrote or read them;
 * Team.release writes them (ledger_store) and hands the agent back. */
typedef struct {
    int eligible; /* -1 not looked at yet; 1 the team may own it (ledger_decide); 0 never (attributes path) */
    int own;
    int kind, triggered, has_interval, has_sensed, moved; /* moved: triggered since own (control, _offset) */
    Py_ssize_t m, heard;
    double kappa, k1, k2, k3, alpha, beta, floor_, tolerance; /* fixed: the gains, the threshold */
    double last_trigger, last_event, interval, control_norm, u[3], u_off[3];
    long triggers, infos;
    PyObject *search; /* _search: a strong reference, NULL for None */
} Ledger;

/* The search Agenda.plan makes of team agent `a` from the ledger (a new reference), the one it keeps, or
 * Py_None (a new reference: the agent's trigger_search decides; the team handed the agent back). */
static PyObject *team_search(PyObject *team, Py_ssize_t a, PyObject *agent, double horizon, double first_span,
                             long long *made);

/* ---- Agenda: the engine's next-event queue (formation_sim.sim.engine._Agenda without a period) -- */

/* A heap entry (time, kind, agent, serial) as the engine's tuples: kind 1 a planned triggering time,
 * kind 0 the frontier of a search under way; agents by their rank among the sorted ids, so that
 * entries order as the tuples do. */
typedef struct {
    double key;
    int kind;
    Py_ssize_t slot;
    long long number;
} Entry;

typedef struct {
    PyObject_HEAD
    double horizon;
    Py_ssize_t n, size, capacity;
    Entry *heap;
    PyObject *ids;       /* the agents' ids, sorted (a tuple) */
    PyObject *slots;     /* id -> rank */
    PyObject **searches; /* per agent: its search, or NULL */
    long long *serial;   /* per agent: the serial of its live entry */
    long long counter;
    PyObject *failed; /* the agent whose search raised in next_time, or None */
    double first_span; /* eta._FIRST_SPAN: plan makes the searches of `plain` agents itself; NaN: it calls trigger_search */
    PyObject *plain;   /* a tuple of the agent types whose trigger_search plan may make in C, or NULL */
    PyObject *rule;    /* the rule type (trigger.ExponentialRule) of the thresholds it may make them for */
    PyObject *team;    /* the engine's Team (link), whose copy of an agent's model a new search starts from */
    Py_ssize_t *team_of; /* per agent (rank): its position in the team, or -1 */
    long long from_team; /* the searches started from the team's copy */
} AgendaObject;

static PyTypeObject AgendaType;

static inline int entry_less(const Entry *a, const Entry *b) {
    if (a->key != b->key)
        return a->key < b->key;
    if (a->kind != b->kind)
        return a->kind < b->kind;
    if (a->slot != b->slot)
        return a->slot < b->slot;
    return a->number < b->number;
}

static int heap_push(AgendaObject *self, Entry e) { /* heapq.heappush */
    if (self->size == self->capacity) {
        Py_ssize_t capacity = self->capacity ? 2 * self->capacity : 64;
        Entry *grown = PyMem_Realloc(self->heap, sizeof(Entry) * (size_t)capacity);
        if (grown == NULL) {
            PyErr_NoMemory();
            return -1;
        }
        self->heap = grown;
        self->capacity = capacity;
    }
    Py_ssize_t pos = self->size++;
    while (pos > 0) {
        Py_ssize_t parent = (pos - 1) >> 1;
        if (!entry_less(&e, &self->heap[parent]))
            break;
        self->heap[pos] = self->heap[parent];
        pos = parent;
    }
    self->heap[pos] = e;
    return 0;
}

static Entry heap_pop(AgendaObject *self) { /* heapq.heappop (size > 0) */
    Entry top = self->heap[0], last = self->heap[--self->size];
    Py_ssize_t pos = 0, n = self->size;
    while (1) {
        Py_ssize_t child = 2 * pos + 1;
        if (child >= n)
            break;
        if (child + 1 < n && entry_less(&self->heap[child + 1], &self->heap[child]))
            child++;
        if (!entry_less(&self->heap[child], &last))
            break;
        self->heap[pos] = self->heap[child];
        pos = child;
    }
    if (n > 0)
        self->heap[pos] = last;
    return top;
}

static PyObject *agenda_new(PyTypeObject *type, PyObject *args, PyObject *kwargs) {
    static char *names[] = {"agent_ids", "horizon", "first_span", "plain", "rule", NULL};
    PyObject *agent_ids = NULL, *plain = NULL, *rule = NULL;
    double horizon = NAN, first_span = NAN;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "|$OddO!O!", names, &agent_ids, &horizon, &first_span,
                                     &PyTuple_Type, &plain, &PyType_Type, &rule))
        return NULL;
    if (agent_ids == NULL || isnan(horizon)) {
        PyErr_SetString(PyExc_TypeError, "Agenda() takes the keyword arguments agent_ids and horizon");
        return NULL;
    }
    PyObject *ids = PySequence_List(agent_ids);
    if (ids == NULL || PyList_Sort(ids) < 0) {
        Py_XDECREF(ids);
        return NULL;
    }
    AgendaObject *self = (AgendaObject *)type->tp_alloc(type, 0);
    if (self == NULL) {
        Py_DECREF(ids);
        return NULL;
    }
    self->horizon = horizon;
    self->first_span = first_span;
    self->plain = Py_XNewRef(plain);
    self->rule = Py_XNewRef(rule);
    self->failed = Py_NewRef(Py_None);
    self->ids = PyList_AsTuple(ids);
    Py_DECREF(ids);
    self->slots = PyDict_New();
    if (self->ids == NULL || self->slots == NULL)
        goto fail;
    self->n = PyTuple_GET_SIZE(self->ids);
    self->searches = PyMem_Calloc((size_t)(self->n ? self->n : 1), sizeof(PyObject *));
    self->serial = PyMem_Calloc((size_t)(self->n ? self->n : 1), sizeof(long long));
    if (self->searches == NULL || self->serial == NULL) {
        PyErr_NoMemory();
        goto fail;
    }
    for (Py_ssize_t k = 0; k < self->n; k++) {
        PyObject *rank = PyLong_FromSsize_t(k);
        if (rank == NULL || PyDict_SetItem(self->slots, PyTuple_GET_ITEM(self->ids, k), rank) < 0) {
            Py_XDECREF(rank);
            goto fail;
        }
        Py_DECREF(rank);
    }
    if (PyDict_GET_SIZE(self->slots) != self->n) {
        PyErr_SetString(PyExc_ValueError, "Agenda: the agent ids are not distinct");
        goto fail;
    }
    return (PyObject *)self;
fail:
    Py_DECREF(self);
    return NULL;
}

static int agenda_traverse(AgendaObject *self, visitproc visit, void *arg) {
    for (Py_ssize_t k = 0; self->searches != NULL && k < self->n; k++)
        Py_VISIT(self->searches[k]);
    Py_VISIT(self->ids);
    Py_VISIT(self->slots);
    Py_VISIT(self->failed);
    Py_VISIT(self->plain);
    Py_VISIT(self->rule);
    Py_VISIT(self->team);
    return 0;
}

static int agenda_clear(AgendaObject *self) {
    for (Py_ssize_t k = 0; self->searches != NULL && k < self->n; k++)
        Py_CLEAR(self->searches[k]);
    Py_CLEAR(self->ids);
    Py_CLEAR(self->slots);
    Py_CLEAR(self->failed);
    Py_CLEAR(self->plain);
    Py_CLEAR(self->rule);
    Py_CLEAR(self->team);
    return 0;
}

static void agenda_dealloc(AgendaObject *self) {
    PyObject_GC_UnTrack(self);
    agenda_clear(self);
    PyMem_Free(self->team_of);
    PyMem_Free(self->searches);
    PyMem_Free(self->serial);
    PyMem_Free(self->heap);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyObject *TRIGGER_SEARCH = NULL, *ADVANCE = NULL, *FRONTIER = NULL; /* method and attribute names */

/* _EventTriggeredAgent.trigger_search(horizon) of a plain agent (an exact type of self->plain) without
 * the safety layer, triggering on `rule` (the exponential threshold, the one the C search knows), where it
 * needs no check that may fail: the agent has triggered and heard every
 * neighbour, and its search is either none (a new _fastcore.Search, made as the method makes it) or a
 * _fastcore.Search of this limit (kept). A new reference; Py_None (a new reference) where the method
 * must decide; NULL on error. */
static PyObject *plain_search(AgendaObject *self, PyObject *agent, Py_ssize_t rank) {
    if (self->team != NULL && self->team_of[rank] >= 0 && !isnan(self->first_span))
        return team_search(self->team, self->team_of[rank], agent, self->horizon, self->first_span,
                           &self->from_team);
    int plain = 0;
    for (Py_ssize_t i = 0; self->plain != NULL && i < PyTuple_GET_SIZE(self->plain); i++)
        plain |= (PyObject *)Py_TYPE(agent) == PyTuple_GET_ITEM(self->plain, i);
    if (!plain || isnan(self->first_span) || self->rule == NULL)
        return Py_NewRef(Py_None);
    PyObject *fast = PyObject_GetAttr(agent, NAMES[N_FAST]), *safety = NULL, *last_trigger = NULL, *heard = NULL,
             *search = NULL, *out = NULL;
    if (fast == NULL || (safety = PyObject_GetAttr(agent, NAMES[N_SAFETY])) == NULL ||
        (last_trigger = PyObject_GetAttr(agent, NAMES[N_LAST_TRIGGER])) == NULL ||
        (heard = PyObject_GetAttr(agent, NAMES[N_EVERYONE_HEARD])) == NULL ||
        (search = PyObject_GetAttr(agent, NAMES[N_SEARCH])) == NULL)
        goto done;
    if (fast != Py_True || safety != Py_None || last_trigger == Py_None || heard != Py_True) {
        out = Py_NewRef(Py_None);
        goto done;
    }
    if (search != Py_None) { /* kept when it has this limit; else the method decides */
        out = Py_IS_TYPE(search, &SearchType) && ((SearchObject *)search)->s.limit == self->horizon
                  ? Py_NewRef(search)
                  : Py_NewRef(Py_None);
        goto done;
    }
    double start, alpha, beta, floor_, tolerance, interval = 0.0;
    PyObject *threshold = PyObject_GetAttr(agent, NAMES[N_THRESHOLD]), *gap = NULL;
    if (threshold != NULL && (PyObject *)Py_TYPE(threshold) != self->rule) { /* another rule: the method */
        Py_DECREF(threshold);
        out = Py_NewRef(Py_None);
        goto done;
    }
    int ok = threshold != NULL && get_double(agent, N_LAST_EVENT, &start) == 0 &&
             get_double(threshold, N_ALPHA, &alpha) == 0 && get_double(threshold, N_BETA, &beta) == 0 &&
             get_double(threshold, N_FLOOR, &floor_) == 0 && get_double(agent, N_TOLERANCE, &tolerance) == 0 &&
             (gap = PyObject_GetAttr(agent, NAMES[N_INTERVAL])) != NULL;
    if (ok && PyObject_IsTrue(gap)) { /* self._interval or 0.0 */
        interval = PyFloat_AsDouble(gap);
        ok = !(interval == -1.0 && PyErr_Occurred());
    }
    Py_XDECREF(threshold);
    Py_XDECREF(gap);
    if (!ok)
        goto done;
    SearchObject *made = (SearchObject *)SearchType.tp_alloc(&SearchType, 0);
    if (made == NULL)
        goto done;
    /* search_new's fields: at the start, no result, no step, the first span, no last step. */
    made->model = Py_NewRef(agent);
    made->start = start;
    made->s = (Search){.alpha = alpha, .beta = beta, .floor = floor_, .limit = self->horizon, .tolerance = tolerance};
    made->st.frontier = start;
    made->st.span = py_max(interval, self->first_span); /* max(self._interval or 0.0, _FIRST_SPAN) */
    made->st.cover_end = -INFINITY;
    made->st.bound_e = NAN;
    made->st.bound_curv = NAN;
    if (PyObject_SetAttr(agent, NAMES[N_SEARCH], (PyObject *)made) < 0) {
        Py_DECREF(made);
        goto done;
    }
    out = (PyObject *)made;
done:
    Py_XDECREF(fast);
    Py_XDECREF(safety);
    Py_XDECREF(last_trigger);
    Py_XDECREF(heard);
    Py_XDECREF(search);
    return out;
}

/* Agent `id` (rank k) planned anew: a new search, queued lazily (next_time searches only as far as the team's
 * next event needs). */
static int plan_one(AgendaObject *self, PyObject *agents, PyObject *id, Py_ssize_t k, PyObject *horizon) {
    PyObject *agent = PyDict_GetItemWithError(agents, id);
    if (agent == NULL) {
        if (!PyErr_Occurred())
            PyErr_Format(PyExc_KeyError, "Agenda.plan: unknown agent %R", id);
        return -1;
    }
    self->counter += 1;
    self->serial[k] = self->counter;
    PyObject *search = plain_search(self, agent, k);
    if (search == Py_None) {
        Py_DECREF(search);
        search = PyObject_CallMethodOneArg(agent, TRIGGER_SEARCH, horizon);
    }
    double frontier;
    if (search != NULL && Py_IS_TYPE(search, &SearchType)) {
        frontier = ((SearchObject *)search)->st.frontier;
    } else if (search != NULL) {
        PyObject *value = PyObject_GetAttr(search, FRONTIER);
        frontier = value ? PyFloat_AsDouble(value) : -1.0;
        Py_XDECREF(value);
        if (PyErr_Occurred())
            Py_CLEAR(search);
    }
    if (search == NULL)
        return -1;
    Py_XSETREF(self->searches[k], search);
    return heap_push(self, (Entry){frontier, 0, k, self->counter});
}

/* plan(agents, changed): _Agenda.plan without a period; `changed` the agents to plan anew, sorted. */
static PyObject *agenda_plan(AgendaObject *self, PyObject *args) {
    PyObject *agents, *changed;
    if (!PyArg_ParseTuple(args, "O!O!", &PyDict_Type, &agents, &PyList_Type, &changed))
        return NULL;
    PyObject *horizon = PyFloat_FromDouble(self->horizon);
    if (horizon == NULL)
        return NULL;
    for (Py_ssize_t c = 0; c < PyList_GET_SIZE(changed); c++) {
        PyObject *id = PyList_GET_ITEM(changed, c);
        PyObject *rank = PyDict_GetItemWithError(self->slots, id);
        Py_ssize_t k = rank ? PyLong_AsSsize_t(rank) : -1;
        if (rank == NULL) {
            if (!PyErr_Occurred())
                PyErr_Format(PyExc_KeyError, "Agenda.plan: unknown agent %R", id);
            Py_DECREF(horizon);
            return NULL;
        }
        if (plan_one(self, agents, id, k, horizon) < 0) {
            Py_DECREF(horizon);
            return NULL;
        }
    }
    Py_DECREF(horizon);
    Py_RETURN_NONE;
}

static int rank_less(const void *a, const void *b) {
    Py_ssize_t x = *(const Py_ssize_t *)a, y = *(const Py_ssize_t *)b;
    return (x > y) - (x < y);
}

/* plan_union(agents, due, receivers): plan(agents, sorted(set(due).union(receivers))), the engine's _run after
 * an event time, the union and its order taken in C: the ranks are the positions among the sorted ids, so
 * sorting them sorts the ids. An id it does not know goes to plan's lookup, which raises its error. */
static PyObject *agenda_plan_union(AgendaObject *self, PyObject *args) {
    PyObject *agents, *due, *receivers;
    if (!PyArg_ParseTuple(args, "O!O!O!", &PyDict_Type, &agents, &PyList_Type, &due, &PyList_Type, &receivers))
        return NULL;
    Py_ssize_t count = PyList_GET_SIZE(due) + PyList_GET_SIZE(receivers);
    Py_ssize_t *ranks = PyMem_Malloc(sizeof(Py_ssize_t) * (size_t)(count > 0 ? count : 1));
    if (ranks == NULL)
        return PyErr_NoMemory();
    for (Py_ssize_t c = 0; c < count; c++) {
        PyObject *id = c < PyList_GET_SIZE(due) ? PyList_GET_ITEM(due, c)
                                                : PyList_GET_ITEM(receivers, c - PyList_GET_SIZE(due));
        PyObject *rank = PyDict_GetItemWithError(self->slots, id);
        if (rank == NULL) { /* a stranger (or an error): the Python union and plan's lookup */
            PyMem_Free(ranks);
            if (PyErr_Occurred())
                return NULL;
            PyObject *changed = PySet_New(due), *sorted = NULL, *out = NULL;
            int added = changed == NULL ? -1 : 0;
            for (Py_ssize_t r = 0; added == 0 && r < PyList_GET_SIZE(receivers); r++)
                added = PySet_Add(changed, PyList_GET_ITEM(receivers, r));
            if (added == 0 && (sorted = PySequence_List(changed)) != NULL && PyList_Sort(sorted) == 0) {
                PyObject *inner = PyTuple_Pack(2, agents, sorted);
                out = inner ? agenda_plan(self, inner) : NULL;
                Py_XDECREF(inner);
            }
            Py_XDECREF(changed);
            Py_XDECREF(sorted);
            return out;
        }
        ranks[c] = PyLong_AsSsize_t(rank);
    }
    qsort(ranks, (size_t)count, sizeof(Py_ssize_t), rank_less);
    PyObject *horizon = PyFloat_FromDouble(self->horizon);
    int status = horizon == NULL ? -1 : 0;
    for (Py_ssize_t c = 0; status == 0 && c < count; c++) {
        if (c > 0 && ranks[c] == ranks[c - 1])
            continue; /* the set's one copy */
        status = plan_one(self, agents, PyTuple_GET_ITEM(self->ids, ranks[c]), ranks[c], horizon);
    }
    Py_XDECREF(horizon);
    PyMem_Free(ranks);
    if (status < 0)
        return NULL;
    Py_RETURN_NONE;
}

/* search.advance(until) -> 1 with *result (done), 0 with *frontier (not yet), -1 on error. */
static int advance_any(PyObject *search, double until, double *result, double *frontier) {
    PyObject *out;
    if (Py_IS_TYPE(search, &SearchType)) {
        out = search_step((SearchObject *)search, until);
    } else {
        PyObject *arg = PyFloat_FromDouble(until);
        out = arg ? PyObject_CallMethodOneArg(search, ADVANCE, arg) : NULL;
        Py_XDECREF(arg);
    }
    if (out == NULL)
        return -1;
    if (out != Py_None) {
        *result = PyFloat_AsDouble(out);
        Py_DECREF(out);
        return PyErr_Occurred() ? -1 : 1;
    }
    Py_DECREF(out);
    if (Py_IS_TYPE(search, &SearchType)) {
        *frontier = ((SearchObject *)search)->st.frontier;
        return 0;
    }
    PyObject *value = PyObject_GetAttr(search, FRONTIER);
    if (value == NULL)
        return -1;
    *frontier = PyFloat_AsDouble(value);
    Py_DECREF(value);
    return PyErr_Occurred() ? -1 : 0;
}

/* next_time(): engine._next_event_time, the earliest planned time of the team, advancing unfinished
 * searches only as needed (ties put searches first, kind 0). A search that raises leaves its agent
 * in `failed` and its error raised. */
static PyObject *agenda_next_time(AgendaObject *self, PyObject *unused) {
    (void)unused;
    double horizon = self->horizon;
    while (self->size > 0) {
        Entry top = self->heap[0];
        if (self->serial[top.slot] != top.number) {
            heap_pop(self);
            continue;
        }
        if (top.kind == 1 || top.key > horizon)
            return PyFloat_FromDouble(top.key);
        heap_pop(self);
        double until = self->size > 0 ? self->heap[0].key : INFINITY, result, frontier;
        PyObject *search = self->searches[top.slot];
        Py_INCREF(search);
        int status = advance_any(search, py_min(until, horizon), &result, &frontier);
        Py_DECREF(search);
        if (status < 0) {
            Py_XSETREF(self->failed, Py_NewRef(PyTuple_GET_ITEM(self->ids, top.slot)));
            return NULL;
        }
        if (status == 0) {
            if (heap_push(self, (Entry){frontier, 0, top.slot, top.number}) < 0)
                return NULL;
        } else if (result <= horizon) {
            if (heap_push(self, (Entry){result, 1, top.slot, top.number}) < 0)
                return NULL;
        }
    }
    return PyFloat_FromDouble(INFINITY);
}

/* pop_due(t): engine._pop_due, the agents planned for exactly t (live entries), taken off, sorted. */
static PyObject *agenda_pop_due(AgendaObject *self, PyObject *arg) {
    double t = PyFloat_AsDouble(arg);
    if (t == -1.0 && PyErr_Occurred())
        return NULL;
    PyObject *due = PyList_New(0);
    while (due != NULL && self->size > 0 && self->heap[0].key == t) {
        Entry e = heap_pop(self);
        if (e.kind == 1 && self->serial[e.slot] == e.number &&
            PyList_Append(due, PyTuple_GET_ITEM(self->ids, e.slot)) < 0)
            Py_CLEAR(due);
    }
    if (due != NULL && PyList_Sort(due) < 0)
        Py_CLEAR(due);
    return due;
}

static PyMemberDef agenda_members[] = {
    {"horizon", T_DOUBLE, offsetof(AgendaObject, horizon), READONLY, "no event is planned past it"},
    {"failed", T_OBJECT, offsetof(AgendaObject, failed), READONLY,
     "the agent whose search raised in next_time, or None"},
    {"from_team", T_LONGLONG, offsetof(AgendaObject, from_team), READONLY,
     "how many new searches were made from the linked team's ledger of their agent's knowledge (link)"},
    {NULL, 0, 0, 0, NULL},
};

static PyObject *agenda_link(AgendaObject *self, PyObject *team);

static PyMethodDef agenda_methods[] = {
    {"plan", (PyCFunction)agenda_plan, METH_VARARGS,
     "plan(agents, changed): a new search for each agent of `changed` (sorted), queued lazily."},
    {"plan_union", (PyCFunction)agenda_plan_union, METH_VARARGS,
     "plan_union(agents, due, receivers): plan(agents, sorted(set(due).union(receivers)))."},
    {"link", (PyCFunction)agenda_link, METH_O,
     "link(team): new searches of the team's agents start from the team's copy of their model (Team)."},
    {"next_time", (PyCFunction)agenda_next_time, METH_NOARGS, "next_time(): the team's earliest planned time."},
    {"pop_due", (PyCFunction)agenda_pop_due, METH_O, "pop_due(t): the agents planned for exactly t, sorted."},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject AgendaType = {
    PyVarObject_HEAD_INIT(NULL, 0).tp_name = "formation_agent.core._fastcore.Agenda",
    .tp_doc = "Agenda(*, agent_ids, horizon): the engine's next-event queue (formation_sim.sim.engine._Agenda "
              "without a period), compiled; the same order, the same times.",
    .tp_basicsize = sizeof(AgendaObject),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC,
    .tp_new = agenda_new,
    .tp_dealloc = (destructor)agenda_dealloc,
    .tp_traverse = (traverseproc)agenda_traverse,
    .tp_clear = (inquiry)agenda_clear,
    .tp_members = agenda_members,
    .tp_methods = agenda_methods,
};

/* ---- Team: the engine's triggers and deliveries at one event time (formation_sim.sim.engine) ----- */

/* A message on its way: TriggerInfo(sender, receiver, stamp, control, rel_position, rel_velocity), its
 * receiver's edge (the sender's slot there) instead of the receiver's lookup. */
typedef struct {
    Py_ssize_t sender, receiver, k;
    double stamp, rel[3], control[3], velocity[3];
} Pending;

typedef struct {
    PyObject_HEAD
    Py_ssize_t n, p;
    PyObject *agents;     /* a tuple, in the world's order */
    PyObject *ids;        /* their ids, a tuple */
    PyObject *index;      /* id -> position */
    PyObject *set_control; /* World.set_control: raises the world's error on a command that is not finite */
    Py_ssize_t *start;    /* start[a] .. start[a + 1]: agent a's edges in `neighbour` and `back` */
    Py_ssize_t *neighbour; /* the neighbour's position, in the agent's neighbour order */
    Py_ssize_t *back;     /* the agent's slot among the neighbour's edges */
    Pending *pending;
    Py_ssize_t size, capacity;
    PyObject *plain;     /* the agent types whose knowledge the team may hold (exact types), a tuple */
    PyObject *rule;      /* the threshold type the compiled search knows (trigger.ExponentialRule) */
    Ledger *ledger;      /* per agent: its knowledge, while the team owns it */
    Edge *edges;         /* agent a's edges from start[a] */
    long long loads, stores; /* ledgers read from and written to the agents' attributes */
} TeamObject;

static PyTypeObject TeamType;

static Py_ssize_t team_position(TeamObject *self, PyObject *id) {
    PyObject *k = PyDict_GetItemWithError(self->index, id);
    if (k == NULL) {
        if (!PyErr_Occurred())
            PyErr_Format(PyExc_KeyError, "Team: unknown agent %R", id);
        return -1;
    }
    return PyLong_AsSsize_t(k);
}

static PyObject *team_new(PyTypeObject *type, PyObject *args, PyObject *kwargs) {
    static char *names[] = {"agents", "ids", "neighbours", "back", "dimension", "set_control", "plain", "rule", NULL};
    PyObject *agents, *ids, *neighbours, *back, *set_control, *plain, *rule;
    Py_ssize_t p;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "$O!O!O!O!nOO!O!", names, &PyTuple_Type, &agents, &PyTuple_Type,
                                     &ids, &PyTuple_Type, &neighbours, &PyTuple_Type, &back, &p, &set_control,
                                     &PyTuple_Type, &plain, &PyType_Type, &rule))
        return NULL;
    Py_ssize_t n = PyTuple_GET_SIZE(agents);
    if (PyTuple_GET_SIZE(ids) != n || PyTuple_GET_SIZE(neighbours) != n || PyTuple_GET_SIZE(back) != n || p < 1 ||
        p > 3) {
        PyErr_SetString(PyExc_ValueError, "Team: agents, ids, neighbours and back of one length, 1 <= dimension <= 3");
        return NULL;
    }
    TeamObject *self = (TeamObject *)type->tp_alloc(type, 0);
    if (self == NULL)
        return NULL;
    self->n = n;
    self->p = p;
    self->agents = Py_NewRef(agents);
    self->ids = Py_NewRef(ids);
    self->set_control = Py_NewRef(set_control);
    self->plain = Py_NewRef(plain);
    self->rule = Py_NewRef(rule);
    self->index = PyDict_New();
    self->start = PyMem_Calloc((size_t)n + 1, sizeof(Py_ssize_t));
    if (self->index == NULL || self->start == NULL)
        goto fail;
    for (Py_ssize_t a = 0; a < n; a++) {
        PyObject *k = PyLong_FromSsize_t(a);
        if (k == NULL || PyDict_SetItem(self->index, PyTuple_GET_ITEM(ids, a), k) < 0) {
            Py_XDECREF(k);
            goto fail;
        }
        Py_DECREF(k);
        PyObject *row = PyTuple_GET_ITEM(neighbours, a), *slots = PyTuple_GET_ITEM(back, a);
        if (!PyTuple_Check(row) || !PyTuple_Check(slots) || PyTuple_GET_SIZE(row) != PyTuple_GET_SIZE(slots)) {
            PyErr_SetString(PyExc_ValueError, "Team: neighbours and back must be tuples of one length per agent");
            goto fail;
        }
        self->start[a + 1] = self->start[a] + PyTuple_GET_SIZE(row);
    }
    Py_ssize_t edges = self->start[n] > 0 ? self->start[n] : 1;
    self->neighbour = PyMem_Malloc(sizeof(Py_ssize_t) * (size_t)edges);
    self->back = PyMem_Malloc(sizeof(Py_ssize_t) * (size_t)edges);
    self->ledger = PyMem_Calloc((size_t)(n > 0 ? n : 1), sizeof(Ledger)); /* none owned */
    self->edges = PyMem_Calloc((size_t)edges, sizeof(Edge));
    if (self->neighbour == NULL || self->back == NULL || self->ledger == NULL || self->edges == NULL) {
        PyErr_NoMemory();
        goto fail;
    }
    for (Py_ssize_t a = 0; a < n; a++)
        self->ledger[a].eligible = -1;
    for (Py_ssize_t a = 0; a < n; a++) {
        PyObject *row = PyTuple_GET_ITEM(neighbours, a), *slots = PyTuple_GET_ITEM(back, a);
        for (Py_ssize_t k = 0; k < PyTuple_GET_SIZE(row); k++) {
            Py_ssize_t b = PyLong_AsSsize_t(PyTuple_GET_ITEM(row, k));
            Py_ssize_t slot = PyLong_AsSsize_t(PyTuple_GET_ITEM(slots, k));
            if (PyErr_Occurred())
                goto fail;
            if (b < 0 || b >= n || slot < 0) {
                PyErr_Format(PyExc_ValueError, "Team: agent %zd's neighbour %zd (slot %zd) out of range", a, b, slot);
                goto fail;
            }
            self->neighbour[self->start[a] + k] = b;
            self->back[self->start[a] + k] = slot;
        }
    }
    return (PyObject *)self;
fail:
    Py_DECREF(self);
    return NULL;
}

static int team_traverse(TeamObject *self, visitproc visit, void *arg) {
    for (Py_ssize_t a = 0; self->ledger != NULL && a < self->n; a++)
        Py_VISIT(self->ledger[a].search);
    Py_VISIT(self->agents);
    Py_VISIT(self->ids);
    Py_VISIT(self->index);
    Py_VISIT(self->set_control);
    Py_VISIT(self->plain);
    Py_VISIT(self->rule);
    return 0;
}

static int team_clear(TeamObject *self) {
    for (Py_ssize_t a = 0; self->ledger != NULL && a < self->n; a++)
        Py_CLEAR(self->ledger[a].search);
    Py_CLEAR(self->agents);
    Py_CLEAR(self->ids);
    Py_CLEAR(self->index);
    Py_CLEAR(self->set_control);
    Py_CLEAR(self->plain);
    Py_CLEAR(self->rule);
    return 0;
}

static void team_dealloc(TeamObject *self) {
    PyObject_GC_UnTrack(self);
    team_clear(self);
    PyMem_Free(self->start);
    PyMem_Free(self->neighbour);
    PyMem_Free(self->back);
    PyMem_Free(self->pending);
    PyMem_Free(self->ledger);
    PyMem_Free(self->edges);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

/* An (n, p) C-contiguous float64 array's buffer (writable when asked); -1 with an error otherwise. */
static int team_buffer(TeamObject *self, PyObject *array, int writable, Py_buffer *view) {
    if (PyObject_GetBuffer(array, view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0)) < 0)
        return -1;
    if (view->ndim != 2 || view->itemsize != 8 || strcmp(view->format, "d") != 0 || view->shape[0] != self->n ||
        view->shape[1] != self->p) {
        PyBuffer_Release(view);
        PyErr_Format(PyExc_ValueError, "Team: the world's arrays must be (%zd, %zd) float64", self->n, self->p);
        return -1;
    }
    return 0;
}

/* What world.sense(agent, neighbour_ids) hands a trigger, read from the world's arrays and checked as
 * read_sensing checks a SensedState (x_i - x_j, q_i - q_j: numpy's subtraction is this one). 0: the
 * Python path decides (an agent not on the plain path, with the safety layer, or sensing it refuses). */
static int team_sensing(TeamObject *self, PyObject *agent, Py_ssize_t a, double t, const double *x, const double *q,
                        Held *h, Sensing *in) {
    long kind, p, fast;
    if (get_long(agent, N_KIND, &kind) < 0 || get_long(agent, N_DIMENSION, &p) < 0 ||
        get_long(agent, N_FAST, &fast) < 0)
        return -1;
    if (!fast || p != self->p || (kind != 1 && kind != 2) || (kind == 2) != (q != NULL) || !isfinite(t))
        return 0;
    in->kind = (int)kind;
    in->p = p;
    in->t = t;
    PyObject *safety = hold(h, PyObject_GetAttr(agent, NAMES[N_SAFETY]));
    PyObject *last_trigger = safety ? hold(h, PyObject_GetAttr(agent, NAMES[N_LAST_TRIGGER])) : NULL;
    PyObject *offsets = last_trigger ? hold(h, PyObject_GetAttr(agent, NAMES[N_OFFSETS3])) : NULL;
    PyObject *capacity = offsets ? hold(h, PyObject_GetAttr(agent, NAMES[N_CAPACITY])) : NULL;
    if (capacity == NULL)
        return -1;
    double last;
    if (safety != Py_None || (last_trigger != Py_None && (!plain_double(last_trigger, &last) || t < last)))
        return 0;
    in->m = self->start[a + 1] - self->start[a];
    if (in->m > MAX_EDGES || !PyList_CheckExact(offsets) || !PyList_CheckExact(capacity) ||
        PyList_GET_SIZE(offsets) != in->m || PyList_GET_SIZE(capacity) != in->m)
        return 0;
    for (Py_ssize_t k = 0; k < in->m; k++) {
        Py_ssize_t b = self->neighbour[self->start[a] + k];
        double d[3], c, sum = 0.0;
        for (Py_ssize_t i = 0; i < 3; i++) {
            in->rel[k][i] = i < p ? x[a * p + i] - x[b * p + i] : 0.0;
            in->extra[k][i] = i < p && q != NULL ? q[a * p + i] - q[b * p + i] : 0.0;
            in->y[k][i] = 0.0;
            if (!isfinite(in->rel[k][i]) || !isfinite(in->extra[k][i]))
                return 0;
        }
        if (read_floats(PyList_GET_ITEM(offsets, k), d, 3, "_offsets3") < 0)
            return -1;
        if (!plain_double(PyList_GET_ITEM(capacity, k), &c))
            return 0;
        for (Py_ssize_t i = 0; i < p; i++) {
            in->y[k][i] = in->rel[k][i] - d[i]; /* y_ij = x_i - x_j - d_ij */
            sum += in->y[k][i] * in->y[k][i];
        }
        in->length[k] = sqrt(sum);
        if (in->length[k] >= c)
            return 0; /* out of its range: the Python path raises */
    }
    return 1;
}

static int team_queue(TeamObject *self, Pending msg) {
    if (self->size == self->capacity) {
        Py_ssize_t capacity = self->capacity ? 2 * self->capacity : 256;
        Pending *grown = PyMem_Realloc(self->pending, sizeof(Pending) * (size_t)capacity);
        if (grown == NULL) {
            PyErr_NoMemory();
            return -1;
        }
        self->pending = grown;
        self->capacity = capacity;
    }
    self->pending[self->size++] = msg;
    return 0;
}

/* Whether the team may hold agent a's knowledge (Ledger): an exact type of `plain` on the plain-float path,
 * of the team's dimension, without the safety layer, triggering on `rule`, with at most MAX_EDGES edges; and
 * what is fixed of it: d_ij, the capacities, the gains, the threshold's α, β, c0 and the tolerance. */
static int ledger_decide(TeamObject *self, Py_ssize_t a, PyObject *agent) {
    Ledger *L = &self->ledger[a];
    Edge *E = self->edges + self->start[a];
    Py_ssize_t m = self->start[a + 1] - self->start[a];
    int plain = 0;
    long kind, p, fast;
    L->eligible = 0;
    for (Py_ssize_t i = 0; i < PyTuple_GET_SIZE(self->plain); i++)
        plain |= (PyObject *)Py_TYPE(agent) == PyTuple_GET_ITEM(self->plain, i);
    if (!plain || m > MAX_EDGES)
        return 0;
    if (get_long(agent, N_KIND, &kind) < 0 || get_long(agent, N_DIMENSION, &p) < 0 ||
        get_long(agent, N_FAST, &fast) < 0)
        return -1;
    if (!fast || p != self->p || (kind != 1 && kind != 2))
        return 0;
    Held h = {.n = 0};
    int status = -1;
    PyObject *safety = hold(&h, PyObject_GetAttr(agent, NAMES[N_SAFETY]));
    PyObject *threshold = safety ? hold(&h, PyObject_GetAttr(agent, NAMES[N_THRESHOLD])) : NULL;
    PyObject *offsets = threshold ? hold(&h, PyObject_GetAttr(agent, NAMES[N_OFFSETS3])) : NULL;
    PyObject *capacity = offsets ? hold(&h, PyObject_GetAttr(agent, NAMES[N_CAPACITY])) : NULL;
    if (capacity == NULL)
        goto done;
    status = 0;
    if (safety != Py_None || (PyObject *)Py_TYPE(threshold) != self->rule || !PyList_CheckExact(offsets) ||
        !PyList_CheckExact(capacity) || PyList_GET_SIZE(offsets) != m || PyList_GET_SIZE(capacity) != m)
        goto done;
    status = -1;
    if (get_double(threshold, N_ALPHA, &L->alpha) < 0 || get_double(threshold, N_BETA, &L->beta) < 0 ||
        get_double(threshold, N_FLOOR, &L->floor_) < 0 || get_double(agent, N_TOLERANCE, &L->tolerance) < 0 ||
        (kind == 1 && get_double(agent, N_SPEED_SCALE, &L->kappa) < 0) ||
        (kind == 2 && (get_double(agent, N_K1, &L->k1) < 0 || get_double(agent, N_K2, &L->k2) < 0 ||
                       get_double(agent, N_K3, &L->k3) < 0)))
        goto done;
    for (Py_ssize_t k = 0; k < m; k++) {
        if (read_floats(PyList_GET_ITEM(offsets, k), E[k].d, 3, "_offsets3") < 0)
            goto done;
        E[k].c = PyFloat_AsDouble(PyList_GET_ITEM(capacity, k));
        if (E[k].c == -1.0 && PyErr_Occurred())
            goto done;
    }
    L->kind = (int)kind;
    L->m = m;
    L->eligible = 1;
    status = 0;
done:
    release(&h);
    return status;
}

/* The agent's attribute `name`: a list of its m edges (a new reference held in h), or NULL with an error. */
static PyObject *edge_list(Held *h, PyObject *agent, int name, Py_ssize_t m) {
    PyObject *list = hold(h, PyObject_GetAttr(agent, NAMES[name]));
    if (list != NULL && (!PyList_CheckExact(list) || PyList_GET_SIZE(list) != m)) {
        PyErr_Format(PyExc_TypeError, "Team: the agent's %U is not a list of its %zd edges", NAMES[name], m);
        return NULL;
    }
    return list;
}

/* A float or None: *has says which. */
static int optional_double(PyObject *value, int *has, double *out) {
    *has = value != Py_None;
    if (!*has)
        return 0;
    *out = PyFloat_AsDouble(value);
    return *out == -1.0 && PyErr_Occurred() ? -1 : 0;
}

/* Agent a's ledger read from its attributes (its knowledge as the Python path or the last release left it);
 * from now on the team owns it. */
static int ledger_load(TeamObject *self, Py_ssize_t a) {
    PyObject *agent = PyTuple_GET_ITEM(self->agents, a);
    Ledger *L = &self->ledger[a];
    Edge *E = self->edges + self->start[a];
    Py_ssize_t m = L->m, width = L->kind == 1 ? WIDTH1 : WIDTH2;
    Held h = {.n = 0};
    int status = -1;
    PyObject *heard = edge_list(&h, agent, N_HEARD, m);
    PyObject *times = heard ? edge_list(&h, agent, N_EDGE_TIME, m) : NULL;
    PyObject *ys = times ? edge_list(&h, agent, N_EDGE_Y, m) : NULL;
    PyObject *us = ys ? edge_list(&h, agent, N_EDGE_U, m) : NULL;
    PyObject *rows = us ? edge_list(&h, agent, N_ROWS, m) : NULL;
    PyObject *qs = rows != NULL && L->kind == 2 ? edge_list(&h, agent, N_EDGE_Q, m) : rows, *sensed = NULL;
    if (qs == NULL)
        goto done;
    if (L->kind == 2 && PyObject_HasAttr(agent, NAMES[N_SENSED_Q]) && /* set by the agent's first trigger */
        (sensed = edge_list(&h, agent, N_SENSED_Q, m)) == NULL)
        goto done;
    PyObject *own = hold(&h, PyObject_GetAttr(agent, NAMES[N_U]));
    PyObject *offset = own ? hold(&h, PyObject_GetAttr(agent, NAMES[N_U_OFFSET])) : NULL;
    PyObject *last_trigger = offset ? hold(&h, PyObject_GetAttr(agent, NAMES[N_LAST_TRIGGER])) : NULL;
    PyObject *interval = last_trigger ? hold(&h, PyObject_GetAttr(agent, NAMES[N_INTERVAL])) : NULL;
    PyObject *search = interval ? hold(&h, PyObject_GetAttr(agent, NAMES[N_SEARCH])) : NULL;
    if (search == NULL || read_floats(own, L->u, 3, "_u") < 0 || read_floats(offset, L->u_off, 3, "_u_offset") < 0 ||
        get_double(agent, N_CONTROL_NORM, &L->control_norm) < 0 || get_double(agent, N_LAST_EVENT, &L->last_event) < 0 ||
        get_long(agent, N_TRIGGERS, &L->triggers) < 0 || get_long(agent, N_INFOS, &L->infos) < 0 ||
        optional_double(last_trigger, &L->triggered, &L->last_trigger) < 0 ||
        optional_double(interval, &L->has_interval, &L->interval) < 0)
        goto done;
    L->heard = 0;
    for (Py_ssize_t k = 0; k < m; k++) {
        PyObject *row = PyList_GET_ITEM(rows, k);
        int heard_k = PyObject_IsTrue(PyList_GET_ITEM(heard, k));
        E[k].time = PyFloat_AsDouble(PyList_GET_ITEM(times, k));
        memset(E[k].q, 0, sizeof E[k].q);
        memset(E[k].sensed_q, 0, sizeof E[k].sensed_q);
        if (heard_k < 0 || (E[k].time == -1.0 && PyErr_Occurred()) ||
            read_floats(PyList_GET_ITEM(ys, k), E[k].y, 3, "_edge_y") < 0 ||
            read_floats(PyList_GET_ITEM(us, k), E[k].u, 3, "_edge_u") < 0 ||
            (L->kind == 2 && read_floats(PyList_GET_ITEM(qs, k), E[k].q, 3, "_edge_q") < 0) ||
            (sensed != NULL && read_floats(PyList_GET_ITEM(sensed, k), E[k].sensed_q, self->p, "_sensed_q") < 0))
            goto done;
        E[k].heard = (char)heard_k;
        L->heard += heard_k;
        E[k].row_set = !(PyTuple_Check(row) && PyTuple_GET_SIZE(row) == 0);
        if (E[k].row_set && read_floats(row, E[k].row, width, "_rows") < 0)
            goto done;
    }
    Py_XSETREF(L->search, search == Py_None ? NULL : Py_NewRef(search));
    L->has_sensed = sensed != NULL;
    L->moved = 0;
    L->own = 1;
    self->loads++;
    status = 0;
done:
    release(&h);
    return status;
}

/* list[k] = value (a new reference, stolen, into a new list); -1 where value is NULL. */
static int list_fill(PyObject *list, Py_ssize_t k, PyObject *value) {
    if (value == NULL)
        return -1;
    PyList_SET_ITEM(list, k, value);
    return 0;
}

/* An edge's row as a tuple (_row(k)), its anchor, y_ij (and ETA-2's q_ij) the very float objects of the edge's
 * time, y and q where they are the same floats (as _row takes them from _edge_time, _edge_y, _edge_q). */
static PyObject *row_tuple(const double *row, Py_ssize_t width, PyObject *time, PyObject *y, PyObject *q) {
    PyObject *t = PyTuple_New(width);
    if (t == NULL)
        return NULL;
    for (Py_ssize_t i = 0; i < width; i++) {
        PyObject *same = i == 0 ? time : i <= 3 ? PyTuple_GET_ITEM(y, i - 1) : i <= 6 && q ? PyTuple_GET_ITEM(q, i - 4) : NULL;
        double v = same ? PyFloat_AS_DOUBLE(same) : 0.0;
        PyObject *x = same && memcmp(&v, row + i, sizeof v) == 0 ? Py_NewRef(same) : float_object(row[i]);
        if (x == NULL) {
            Py_DECREF(t);
            return NULL;
        }
        PyTuple_SET_ITEM(t, i, x);
    }
    PyObject_GC_UnTrack(t); /* floats only: as floats_tuple */
    return t;
}

/* Agent a's attributes written from its ledger, as the Python path leaves them (the same floats), and the
 * agent handed back: its attributes are its knowledge again (a change to them is read at the next load). */
static int ledger_store(TeamObject *self, Py_ssize_t a) {
    Ledger *L = &self->ledger[a];
    if (!L->own)
        return 0;
    PyObject *agent = PyTuple_GET_ITEM(self->agents, a);
    Edge *E = self->edges + self->start[a];
    Py_ssize_t m = L->m, p = self->p, width = L->kind == 1 ? WIDTH1 : WIDTH2;
    int eta2 = L->kind == 2, sensed = eta2 && L->has_sensed;
    PyObject *lists[7] = {PyList_New(m), PyList_New(m), PyList_New(m), PyList_New(m), PyList_New(m),
                          eta2 ? PyList_New(m) : NULL, sensed ? PyList_New(m) : NULL};
    static const int names[7] = {N_HEARD, N_EDGE_TIME, N_EDGE_Y, N_EDGE_U, N_ROWS, N_EDGE_Q, N_SENSED_Q};
    int status = -1, count = sensed ? 7 : eta2 ? 6 : 5;
    for (int i = 0; i < count; i++)
        if (lists[i] == NULL)
            goto done;
    for (Py_ssize_t k = 0; k < m; k++) {
        if (list_fill(lists[0], k, PyBool_FromLong(E[k].heard)) < 0 || list_fill(lists[1], k, float_object(E[k].time)) < 0 ||
            list_fill(lists[2], k, floats_tuple(E[k].y, 3)) < 0 || list_fill(lists[3], k, floats_tuple(E[k].u, 3)) < 0 ||
            (eta2 && list_fill(lists[5], k, floats_tuple(E[k].q, 3)) < 0) ||
            list_fill(lists[4], k,
                      E[k].row_set ? row_tuple(E[k].row, width, PyList_GET_ITEM(lists[1], k),
                                               PyList_GET_ITEM(lists[2], k), eta2 ? PyList_GET_ITEM(lists[5], k) : NULL)
                                   : PyTuple_New(0)) < 0 ||
            (sensed && list_fill(lists[6], k, floats_tuple(E[k].sensed_q, p)) < 0))
            goto done;
    }
    for (int i = 0; i < count; i++) {
        PyObject *list = lists[i];
        lists[i] = NULL;
        if (set_attr(agent, names[i], list) < 0)
            goto done;
    }
    if (L->moved) { /* trigger's np.array(control), np.array(offset) */
        PyObject *command = floats_tuple(L->u, p), *own = floats_tuple(L->u_off, p);
        int rc = command == NULL || own == NULL ||
                 set_attr(agent, N_CONTROL, PyObject_CallOneArg(NP_ARRAY, command)) < 0 ||
                 set_attr(agent, N_OFFSET, PyObject_CallOneArg(NP_ARRAY, own)) < 0;
        Py_XDECREF(command);
        Py_XDECREF(own);
        if (rc)
            goto done;
    }
    if (set_attr(agent, N_U, floats_tuple(L->u, 3)) < 0 || set_attr(agent, N_U_OFFSET, floats_tuple(L->u_off, 3)) < 0 ||
        set_attr(agent, N_CONTROL_NORM, PyFloat_FromDouble(L->control_norm)) < 0 ||
        set_attr(agent, N_LAST_TRIGGER, L->triggered ? PyFloat_FromDouble(L->last_trigger) : Py_NewRef(Py_None)) < 0 ||
        set_attr(agent, N_LAST_EVENT, PyFloat_FromDouble(L->last_event)) < 0 ||
        set_attr(agent, N_INTERVAL, L->has_interval ? PyFloat_FromDouble(L->interval) : Py_NewRef(Py_None)) < 0 ||
        set_attr(agent, N_TRIGGERS, PyLong_FromLong(L->triggers)) < 0 ||
        set_attr(agent, N_INFOS, PyLong_FromLong(L->infos)) < 0 ||
        set_attr(agent, N_SEARCH, Py_NewRef(L->search != NULL ? L->search : Py_None)) < 0 ||
        (L->heard == m && set_attr(agent, N_EVERYONE_HEARD, Py_NewRef(Py_True)) < 0))
        goto done;
    L->own = 0;
    Py_CLEAR(L->search);
    self->stores++;
    status = 0;
done:
    for (int i = 0; i < 7; i++)
        Py_XDECREF(lists[i]);
    return status;
}

/* Agent a owned (its ledger loaded where it is not yet): 1; 0 where the team leaves it to its attributes. */
static int ledger_owned(TeamObject *self, Py_ssize_t a) {
    Ledger *L = &self->ledger[a];
    if (L->eligible < 0 && ledger_decide(self, a, PyTuple_GET_ITEM(self->agents, a)) < 0)
        return -1;
    if (!L->eligible)
        return 0;
    return L->own || ledger_load(self, a) == 0 ? 1 : -1;
}

static int ledger_counters(PyObject *team, Py_ssize_t a, long *triggers, long *infos) {
    TeamObject *self = (TeamObject *)team;
    if (a < 0 || a >= self->n || !self->ledger[a].own)
        return 0;
    *triggers = self->ledger[a].triggers;
    *infos = self->ledger[a].infos;
    return 1;
}

/* The model a search reads (read_model's layout) from agent a's ledger: its packed rows, _u_offset,
 * _control_norm, k1..k3 (every row is set: the agent has triggered). */
static int ledger_model(PyObject *team, Py_ssize_t a, Model *md) {
    TeamObject *self = (TeamObject *)team;
    Ledger *L = &self->ledger[a];
    Edge *E = self->edges + self->start[a];
    Py_ssize_t width = L->kind == 1 ? WIDTH1 : WIDTH2, n = L->m > 0 ? L->m : 1;
    md->rows = PyMem_Malloc(sizeof(double) * (size_t)(n * (width + 5)));
    if (md->rows == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    md->kind = L->kind;
    md->m = L->m;
    md->probe = md->rows + n * width;
    md->speeds = md->probe + 4 * n;
    for (Py_ssize_t k = 0; k < L->m; k++)
        memcpy(md->rows + k * width, E[k].row, sizeof(double) * (size_t)width);
    memcpy(md->u_off, L->u_off, sizeof md->u_off);
    md->control_norm = L->control_norm;
    if (L->kind == 2) {
        md->k1 = L->k1;
        md->k2 = L->k2;
        md->k3 = L->k3;
    }
    return 0;
}

/* Agent a's trigger at t from the world's arrays on its ledger: what team_sensing, take_sensing and
 * after_trigger do on its attributes (_EventTriggeredAgent.trigger: the same checks, updates and floats),
 * the command into `control`. 1 done, 0 left to the Python path (a trigger back in time, a state that is not
 * finite, an edge out of its range: nothing changed). */
static int ledger_trigger(TeamObject *self, Py_ssize_t a, double t, const double *x, const double *q, Sensing *in,
                          double *control) {
    Ledger *L = &self->ledger[a];
    Edge *E = self->edges + self->start[a];
    Py_ssize_t m = L->m, p = self->p;
    if ((L->kind == 2) != (q != NULL) || !isfinite(t) || (L->triggered && t < L->last_trigger))
        return 0;
    in->kind = L->kind;
    in->p = p;
    in->m = m;
    in->t = t;
    for (Py_ssize_t k = 0; k < m; k++) {
        Py_ssize_t b = self->neighbour[self->start[a] + k];
        double sum = 0.0;
        for (Py_ssize_t i = 0; i < 3; i++) {
            in->rel[k][i] = i < p ? x[a * p + i] - x[b * p + i] : 0.0;
            in->extra[k][i] = i < p && q != NULL ? q[a * p + i] - q[b * p + i] : 0.0;
            in->y[k][i] = 0.0;
            if (!isfinite(in->rel[k][i]) || !isfinite(in->extra[k][i]))
                return 0;
        }
        for (Py_ssize_t i = 0; i < p; i++) {
            in->y[k][i] = in->rel[k][i] - E[k].d[i]; /* y_ij = x_i - x_j - d_ij */
            sum += in->y[k][i] * in->y[k][i];
        }
        in->length[k] = sqrt(sum);
        if (in->length[k] >= E[k].c)
            return 0; /* out of its range: the Python path raises */
    }
    double total[3] = {0.0, 0.0, 0.0}, offset[3];
    for (Py_ssize_t k = 0; k < m; k++) { /* _weighted_sum */
        double r = in->length[k], c = E[k].c;
        double gap = c - r;
        double w = (2.0 * c - r) / (gap * gap); /* ω_ij (fij) */
        for (Py_ssize_t i = 0; i < p; i++)
            total[i] += w * (L->kind == 1 ? in->y[k][i] : L->k1 * in->y[k][i] + L->k2 * in->extra[k][i]);
    }
    for (Py_ssize_t i = 0; i < 3; i++) {
        offset[i] = i < p ? -total[i] : 0.0;                                  /* (uxsingle) / (uxdouble) */
        control[i] = i < p && L->kind == 1 ? L->kappa * offset[i] : offset[i]; /* κ u_i (ETA-1) */
    }
    for (Py_ssize_t k = 0; k < m; k++) { /* [t] * m, the sensed y_ij (ETA-2: q_ij) and the rows (_row) */
        double *row = E[k].row, *uj = E[k].u;
        E[k].time = t;
        memcpy(E[k].y, in->y[k], sizeof E[k].y);
        if (L->kind == 2) { /* Eta2Agent._update (_sensed_q, _edge_q) */
            memcpy(E[k].q, in->extra[k], sizeof E[k].q);
            memcpy(E[k].sensed_q, in->extra[k], sizeof E[k].sensed_q);
        }
        fill_row(row, L->kind, t, E[k].y, E[k].q, control, uj, E[k].c);
        E[k].row_set = 1;
    }
    memcpy(L->u, control, sizeof L->u);
    memcpy(L->u_off, offset, sizeof L->u_off);
    L->control_norm = sqrt(offset[0] * offset[0] + offset[1] * offset[1] + offset[2] * offset[2]);
    if (L->triggered && t > L->last_trigger) {
        L->interval = t - L->last_trigger;
        L->has_interval = 1;
    }
    L->last_trigger = t;
    L->triggered = 1;
    if (t > L->last_event) /* max(self.last_event, t) */
        L->last_event = t;
    Py_CLEAR(L->search);
    L->triggers += 1;
    L->moved = 1;
    L->has_sensed |= L->kind == 2;
    return 1;
}

/* A queued message taken on its receiver's ledger: read_message's checks, take_message and after_message
 * (_EventTriggeredAgent.receive: the same updates and floats). 1 taken, 0 left to the Python receive (a
 * message back in time: nothing changed), -1 error. */
static int ledger_receive(TeamObject *self, const Pending *msg) {
    Ledger *L = &self->ledger[msg->receiver];
    if (msg->k >= L->m)
        return 0;
    Edge *E = self->edges + self->start[msg->receiver] + msg->k;
    Py_ssize_t p = self->p;
    if (msg->stamp < E->time || (L->triggered && msg->stamp < L->last_trigger))
        return 0; /* back in time: the Python path raises */
    double y[3] = {0.0, 0.0, 0.0}, uj[3] = {0.0, 0.0, 0.0}, q[3] = {0.0, 0.0, 0.0}, *u = L->u, *row = E->row;
    for (Py_ssize_t i = 0; i < p; i++) {
        y[i] = -msg->rel[i] - E->d[i]; /* the message carries x_j - x_i; the edge state is x_i - x_j - d_ij */
        uj[i] = msg->control[i];
        q[i] = -msg->velocity[i];
    }
    if (L->kind == 2) /* Eta2Agent._receive_extra */
        memcpy(E->q, q, sizeof E->q);
    L->heard += !E->heard;
    E->heard = 1;
    E->time = msg->stamp;
    memcpy(E->y, y, sizeof E->y);
    memcpy(E->u, uj, sizeof E->u);
    fill_row(row, L->kind, msg->stamp, y, q, u, uj, E->c);
    E->row_set = 1;
    L->infos += 1;
    if (msg->stamp > L->last_event) /* max(self.last_event, stamp) */
        L->last_event = msg->stamp;
    if (L->search != NULL) { /* dropped unless already due at or before this time */
        int done;
        double due = INFINITY;
        if (Py_IS_TYPE(L->search, &SearchType)) {
            done = ((SearchObject *)L->search)->st.has_result;
            due = ((SearchObject *)L->search)->st.result;
        } else {
            PyObject *result = PyObject_GetAttr(L->search, NAMES[N_RESULT]);
            if (result == NULL)
                return -1;
            done = result != Py_None;
            if (done)
                due = PyFloat_AsDouble(result);
            Py_DECREF(result);
            if (PyErr_Occurred())
                return -1;
        }
        if (!(done && due <= msg->stamp))
            Py_CLEAR(L->search);
    }
    return 1;
}

/* The command into the world's u (World.set_control; one that is not finite is refused by the world, in its
 * words) and the trigger's information queued for deliver. */
static int team_send(TeamObject *self, Py_ssize_t a, const Sensing *in, const double *control, double *u) {
    int finite = 1;
    for (Py_ssize_t i = 0; i < in->p; i++)
        finite &= isfinite(control[i]) != 0;
    if (!finite) {
        PyObject *values = floats_tuple(control, in->p);
        PyObject *command = values ? PyObject_CallOneArg(NP_ARRAY, values) : NULL;
        PyObject *out = command ? PyObject_CallFunctionObjArgs(self->set_control, PyTuple_GET_ITEM(self->ids, a),
                                                               command, NULL)
                                : NULL;
        Py_XDECREF(values);
        Py_XDECREF(command);
        if (out != NULL) {
            Py_DECREF(out);
            PyErr_SetString(PyExc_RuntimeError, "World.set_control took a command that is not finite");
        }
        return -1;
    }
    for (Py_ssize_t i = 0; i < in->p; i++)
        u[a * in->p + i] = control[i];
    for (Py_ssize_t k = 0; k < in->m; k++) {
        Pending msg = {.sender = a, .receiver = self->neighbour[self->start[a] + k],
                       .k = self->back[self->start[a] + k], .stamp = in->t};
        for (Py_ssize_t i = 0; i < 3; i++) {
            msg.rel[i] = in->rel[k][i];
            msg.control[i] = control[i];
            msg.velocity[i] = in->extra[k][i];
        }
        if (team_queue(self, msg) < 0)
            return -1;
    }
    return 1;
}

/* One agent's trigger at t from the world's arrays: on its ledger where the team owns its knowledge, else on
 * its attributes (team_sensing, take_sensing, after_trigger); then its command and messages (team_send). 1
 * done, 0 left to the Python path (the agent handed back first), -1 error. */
static int team_trigger_one(TeamObject *self, Py_ssize_t a, PyObject *t_obj, double t, const double *x,
                            const double *q, double *u, Sensing *in) {
    PyObject *agent = PyTuple_GET_ITEM(self->agents, a);
    double control[3], offset[3];
    int status = ledger_owned(self, a);
    if (status == 1) {
        status = ledger_trigger(self, a, t, x, q, in, control);
        if (status == 0 && ledger_store(self, a) < 0)
            return -1;
    } else if (status == 0) {
        Held h = {.n = 0};
        status = team_sensing(self, agent, a, t, x, q, &h, in);
        if (status == 1 && (take_sensing(agent, &h, in, control, offset) < 0 || after_trigger(agent, &h, t_obj) < 0))
            status = -1;
        release(&h);
    }
    return status == 1 ? team_send(self, a, in, control, u) : status;
}

/* trigger(due, start, t, x, q, u): the agents due[start:] trigger at t in turn, as the engine's
 * _trigger_and_deliver lets them (sense, trigger, set_control), until one the compiled path does not
 * take: its position in `due` (len(due): all done), for the Python path. */
static PyObject *team_trigger(TeamObject *self, PyObject *args) {
    PyObject *due, *t_obj, *x_obj, *q_obj, *u_obj;
    Py_ssize_t first;
    if (!PyArg_ParseTuple(args, "O!nO!OOO", &PyList_Type, &due, &first, &PyFloat_Type, &t_obj, &x_obj, &q_obj,
                          &u_obj))
        return NULL;
    Py_buffer xv, qv, uv;
    if (team_buffer(self, x_obj, 0, &xv) < 0)
        return NULL;
    if (q_obj != Py_None && team_buffer(self, q_obj, 0, &qv) < 0) {
        PyBuffer_Release(&xv);
        return NULL;
    }
    if (team_buffer(self, u_obj, 1, &uv) < 0) {
        PyBuffer_Release(&xv);
        if (q_obj != Py_None)
            PyBuffer_Release(&qv);
        return NULL;
    }
    Sensing *in = PyMem_Malloc(sizeof(Sensing));
    double t = PyFloat_AS_DOUBLE(t_obj);
    Py_ssize_t pos = first, count = PyList_GET_SIZE(due);
    int status = in == NULL ? (PyErr_NoMemory(), -1) : 1;
    for (; status == 1 && pos < count; pos++) {
        Py_ssize_t a = team_position(self, PyList_GET_ITEM(due, pos));
        status = a < 0 ? -1
                       : team_trigger_one(self, a, t_obj, t, xv.buf, q_obj == Py_None ? NULL : qv.buf, uv.buf, in);
        if (status != 1)
            break;
    }
    PyMem_Free(in);
    PyBuffer_Release(&xv);
    PyBuffer_Release(&uv);
    if (q_obj != Py_None)
        PyBuffer_Release(&qv);
    if (status < 0)
        return NULL;
    return PyLong_FromSsize_t(pos);
}

/* A queued message as the TriggerInfo the trigger would have sent (for the Python receive). */
static PyObject *team_info(TeamObject *self, const Pending *msg, int kind) {
    PyObject *stamp = PyFloat_FromDouble(msg->stamp), *control = floats_tuple(msg->control, self->p);
    PyObject *rel = floats_tuple(msg->rel, self->p);
    PyObject *velocity = kind == 1 ? Py_NewRef(Py_None) : floats_tuple(msg->velocity, self->p);
    PyObject *info = NULL;
    if (stamp != NULL && control != NULL && rel != NULL && velocity != NULL) {
        PyObject *args[6] = {PyTuple_GET_ITEM(self->ids, msg->sender), PyTuple_GET_ITEM(self->ids, msg->receiver),
                             stamp, control, rel, velocity};
        info = make_record(TRIGGER_INFO, DIRECT_INFO, INFO_NAMES, args);
    }
    Py_XDECREF(stamp);
    Py_XDECREF(control);
    Py_XDECREF(rel);
    Py_XDECREF(velocity);
    return info;
}

/* One queued message taken by its receiver: on its ledger where the team owns its knowledge, else on its
 * attributes (read_message's checks, take_message, after_message); a message they do not take goes, as a
 * TriggerInfo, to the receiver's receive (handed back first), which raises its error. */
static int team_deliver_one(TeamObject *self, const Pending *pending) {
    PyObject *agent = PyTuple_GET_ITEM(self->agents, pending->receiver);
    int owned = ledger_owned(self, pending->receiver), status;
    long kind, p, fast;
    if (owned < 0)
        return -1;
    if (owned) {
        status = ledger_receive(self, pending);
        if (status != 0)
            return status < 0 ? -1 : 0;
        if (ledger_store(self, pending->receiver) < 0)
            return -1;
    }
    Held h = {.n = 0};
    status = -1;
    if (get_long(agent, N_KIND, &kind) < 0 || get_long(agent, N_DIMENSION, &p) < 0 ||
        get_long(agent, N_FAST, &fast) < 0)
        return -1;
    Message msg = {.k = pending->k, .p = p, .kind = (int)kind, .stamp = pending->stamp};
    memcpy(msg.rel, pending->rel, sizeof msg.rel);
    memcpy(msg.control, pending->control, sizeof msg.control);
    memcpy(msg.velocity, pending->velocity, sizeof msg.velocity);
    int plain = !owned && fast && p == self->p && (kind == 1 || kind == 2);
    PyObject *edge_time = plain ? hold(&h, PyObject_GetAttr(agent, NAMES[N_EDGE_TIME])) : NULL;
    PyObject *last_trigger = edge_time ? hold(&h, PyObject_GetAttr(agent, NAMES[N_LAST_TRIGGER])) : NULL;
    if (plain && last_trigger == NULL)
        goto done;
    double edge, last;
    plain = plain && PyList_CheckExact(edge_time) && msg.k < PyList_GET_SIZE(edge_time) &&
            plain_double(PyList_GET_ITEM(edge_time, msg.k), &edge) && msg.stamp >= edge &&
            (last_trigger == Py_None || (plain_double(last_trigger, &last) && msg.stamp >= last));
    if (plain) {
        status = take_message(agent, &h, &msg) < 0 || after_message(agent, &h, msg.stamp) < 0 ? -1 : 0;
    } else {
        PyObject *info = hold(&h, team_info(self, pending, (int)kind));
        PyObject *out = info ? PyObject_CallMethodOneArg(agent, NAMES[N_RECEIVE], info) : NULL;
        status = out == NULL ? -1 : 0;
        Py_XDECREF(out);
    }
done:
    release(&h);
    return status;
}

/* deliver(): every queued message reaches its receiver, in the order sent; their ids, in that order. */
static PyObject *team_deliver(TeamObject *self, PyObject *unused) {
    (void)unused;
    PyObject *receivers = PyList_New(self->size);
    for (Py_ssize_t i = 0; receivers != NULL && i < self->size; i++) {
        PyList_SET_ITEM(receivers, i, Py_NewRef(PyTuple_GET_ITEM(self->ids, self->pending[i].receiver)));
        if (team_deliver_one(self, &self->pending[i]) < 0)
            Py_CLEAR(receivers);
    }
    self->size = 0; /* delivered, or the run ends with the error */
    return receivers;
}

static PyObject *team_search(PyObject *team, Py_ssize_t a, PyObject *agent, double horizon, double first_span,
                             long long *made) {
    TeamObject *self = (TeamObject *)team;
    if (a < 0 || a >= self->n || PyTuple_GET_ITEM(self->agents, a) != agent)
        return Py_NewRef(Py_None);
    int owned = ledger_owned(self, a);
    if (owned <= 0)
        return owned < 0 ? NULL : Py_NewRef(Py_None);
    Ledger *L = &self->ledger[a];
    if (L->search != NULL && Py_IS_TYPE(L->search, &SearchType) && ((SearchObject *)L->search)->s.limit == horizon)
        return Py_NewRef(L->search); /* trigger_search keeps the search of this limit */
    if (L->search != NULL || !L->triggered || L->heard < L->m) /* the method decides, or raises its error */
        return ledger_store(self, a) < 0 ? NULL : Py_NewRef(Py_None);
    SearchObject *search = (SearchObject *)SearchType.tp_alloc(&SearchType, 0);
    if (search == NULL)
        return NULL;
    /* search_new's fields: at the start (last_event), no result, no step, the first span
     * max(self._interval or 0.0, _FIRST_SPAN), no last step; the model from the ledger. */
    search->model = Py_NewRef(agent);
    search->start = L->last_event;
    search->s = (Search){.alpha = L->alpha, .beta = L->beta, .floor = L->floor_, .limit = horizon,
                         .tolerance = L->tolerance};
    search->st.frontier = L->last_event;
    search->st.span = py_max(L->has_interval ? L->interval : 0.0, first_span);
    search->st.cover_end = -INFINITY;
    search->st.bound_e = NAN;
    search->st.bound_curv = NAN;
    if (ledger_model(team, a, &search->md) < 0) {
        Py_DECREF(search);
        return NULL;
    }
    search->known_triggers = L->triggers;
    search->known_infos = L->infos;
    search->team = Py_NewRef(team);
    search->team_pos = a;
    L->search = Py_NewRef(search);
    *made += 1;
    return (PyObject *)search;
}

/* release(*ids): the agents' attributes written from the team's ledger (all agents without ids) and the
 * agents handed back; the engine calls it before a Python method of an agent reads or changes its knowledge,
 * and at the end of a run. */
static PyObject *team_release(TeamObject *self, PyObject *args) {
    Py_ssize_t count = PyTuple_GET_SIZE(args);
    for (Py_ssize_t i = 0; i < (count > 0 ? count : self->n); i++) {
        Py_ssize_t a = count > 0 ? team_position(self, PyTuple_GET_ITEM(args, i)) : i;
        if (a < 0 || ledger_store(self, a) < 0)
            return NULL;
    }
    Py_RETURN_NONE;
}

/* Agenda.link(team): new searches of the team's agents start from the team's copy of their model. */
static PyObject *agenda_link(AgendaObject *self, PyObject *team) {
    if (!Py_IS_TYPE(team, &TeamType)) {
        PyErr_Format(PyExc_TypeError, "Agenda.link takes a Team, got %R", team);
        return NULL;
    }
    Py_ssize_t *team_of = PyMem_Malloc(sizeof(Py_ssize_t) * (size_t)(self->n ? self->n : 1));
    if (team_of == NULL)
        return PyErr_NoMemory();
    for (Py_ssize_t k = 0; k < self->n; k++) {
        PyObject *position = PyDict_GetItemWithError(((TeamObject *)team)->index, PyTuple_GET_ITEM(self->ids, k));
        team_of[k] = position == NULL ? -1 : PyLong_AsSsize_t(position);
        if (PyErr_Occurred()) {
            PyMem_Free(team_of);
            return NULL;
        }
    }
    PyMem_Free(self->team_of);
    self->team_of = team_of;
    Py_XSETREF(self->team, Py_NewRef(team));
    Py_RETURN_NONE;
}

static PyMemberDef team_members[] = {
    {"loads", T_LONGLONG, offsetof(TeamObject, loads), READONLY, "ledgers read from the agents' attributes"},
    {"stores", T_LONGLONG, offsetof(TeamObject, stores), READONLY, "ledgers written to the agents' attributes"},
    {NULL, 0, 0, 0, NULL},
};

static PyMethodDef team_methods[] = {
    {"trigger", (PyCFunction)team_trigger, METH_VARARGS,
     "trigger(due, start, t, x, q, u): due[start:] trigger at t from the world's arrays until one the compiled "
     "path does not take; its position (len(due): all)."},
    {"deliver", (PyCFunction)team_deliver, METH_NOARGS,
     "deliver(): the queued triggering information reaches its receivers; their ids, in the order sent."},
    {"release", (PyCFunction)team_release, METH_VARARGS,
     "release(*ids): the agents' attributes written from the team's ledger of their knowledge (every agent "
     "without ids), the agents handed back."},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject TeamType = {
    PyVarObject_HEAD_INIT(NULL, 0).tp_name = "formation_agent.core._fastcore.Team",
    .tp_doc = "Team(*, agents, ids, neighbours, back, dimension, set_control): the engine's triggers and "
              "deliveries at an event time (formation_sim.sim.engine._trigger_and_deliver), compiled.",
    .tp_basicsize = sizeof(TeamObject),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC,
    .tp_new = team_new,
    .tp_dealloc = (destructor)team_dealloc,
    .tp_traverse = (traverseproc)team_traverse,
    .tp_clear = (inquiry)team_clear,
    .tp_methods = team_methods,
    .tp_members = team_members,
};

/* team_edges(agents, ids): what the engine's _team hands Team for agents[a] (id ids[a]): (neighbours, back),
 * per agent the positions of its neighbour_ids in `ids` and its slot among each neighbour's neighbour_ids (the
 * first, as tuple.index finds it); None where a neighbour is not in `ids` or does not list the agent back. */
static PyObject *team_edges(PyObject *self, PyObject *args) {
    (void)self;
    PyObject *agents, *ids;
    if (!PyArg_ParseTuple(args, "O!O!", &PyTuple_Type, &agents, &PyTuple_Type, &ids))
        return NULL;
    Py_ssize_t n = PyTuple_GET_SIZE(agents);
    if (PyTuple_GET_SIZE(ids) != n) {
        PyErr_SetString(PyExc_ValueError, "team_edges: agents and ids of one length");
        return NULL;
    }
    PyObject *index = PyDict_New(), *lists = PyTuple_New(n), *neighbours = PyTuple_New(n), *back = PyTuple_New(n);
    PyObject *out = NULL;
    if (index == NULL || lists == NULL || neighbours == NULL || back == NULL)
        goto done;
    for (Py_ssize_t a = 0; a < n; a++) {
        PyObject *k = PyLong_FromSsize_t(a);
        PyObject *own = k ? PyObject_GetAttr(PyTuple_GET_ITEM(agents, a), NAMES[N_NEIGHBOUR_IDS]) : NULL;
        if (own == NULL || PyDict_SetItem(index, PyTuple_GET_ITEM(ids, a), k) < 0) {
            Py_XDECREF(k);
            Py_XDECREF(own);
            goto done;
        }
        Py_DECREF(k);
        PyTuple_SET_ITEM(lists, a, own);
        if (!PyTuple_Check(own)) {
            PyErr_Format(PyExc_TypeError, "team_edges: agent %R's neighbour_ids is not a tuple", PyTuple_GET_ITEM(ids, a));
            goto done;
        }
    }
    for (Py_ssize_t a = 0; a < n; a++) {
        PyObject *own = PyTuple_GET_ITEM(lists, a), *me = PyTuple_GET_ITEM(ids, a);
        Py_ssize_t m = PyTuple_GET_SIZE(own);
        PyObject *row = PyTuple_New(m), *slots = PyTuple_New(m);
        if (row == NULL || slots == NULL) {
            Py_XDECREF(row);
            Py_XDECREF(slots);
            goto done;
        }
        PyTuple_SET_ITEM(neighbours, a, row);
        PyTuple_SET_ITEM(back, a, slots);
        for (Py_ssize_t k = 0; k < m; k++) {
            PyObject *position = PyDict_GetItemWithError(index, PyTuple_GET_ITEM(own, k));
            if (position == NULL) {
                out = PyErr_Occurred() ? NULL : Py_NewRef(Py_None); /* a stranger: the Python path */
                goto done;
            }
            PyObject *theirs = PyTuple_GET_ITEM(lists, PyLong_AsSsize_t(position));
            Py_ssize_t slot = -1;
            for (Py_ssize_t l = 0; slot < 0 && l < PyTuple_GET_SIZE(theirs); l++) {
                int same = PyObject_RichCompareBool(PyTuple_GET_ITEM(theirs, l), me, Py_EQ);
                if (same < 0)
                    goto done;
                if (same)
                    slot = l;
            }
            if (slot < 0) {
                out = Py_NewRef(Py_None); /* not listed back: the Python path */
                goto done;
            }
            PyObject *number = PyLong_FromSsize_t(slot);
            if (number == NULL)
                goto done;
            PyTuple_SET_ITEM(row, k, Py_NewRef(position));
            PyTuple_SET_ITEM(slots, k, number);
        }
    }
    out = PyTuple_Pack(2, neighbours, back);
done:
    Py_XDECREF(index);
    Py_XDECREF(lists);
    Py_XDECREF(neighbours);
    Py_XDECREF(back);
    return out;
}

/* ---- the world's closed-form step (formation_sim.sim.world.World._propagate) -------------- */

#define N_WORLD_SERIES 14
static double WORLD_SERIES[N_WORLD_SERIES]; /* closed_form._SERIES: 1/(k+2)!, k = 0..13 */
static double WORLD_SERIES_LIMIT = NAN;
static PyObject *NP_EXPM1 = NULL; /* numpy.expm1: the function closed_form.advance_double calls */

/* configure_world(*, expm1, series, series_limit): what `advance` computes the factors with, from
 * their one source (closed_form.py, numpy). */
static PyObject *configure_world(PyObject *self, PyObject *args, PyObject *kwargs) {
    (void)self;
    static char *names[] = {"expm1", "series", "series_limit", NULL};
    PyObject *expm1_, *coefficients;
    double limit;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "$OOd", names, &expm1_, &coefficients, &limit))
        return NULL;
    if (read_floats(coefficients, WORLD_SERIES, N_WORLD_SERIES, "series") < 0)
        return NULL;
    WORLD_SERIES_LIMIT = limit;
    Py_XSETREF(NP_EXPM1, Py_NewRef(expm1_));
    Py_RETURN_NONE;
}

/* A C-contiguous float64 buffer of `count` items (writable when asked); 0 without an error set where
 * it is not one (the caller falls back to numpy), -1 on another error. */
static int world_buffer(PyObject *array, Py_ssize_t count, int writable, Py_buffer *view) {
    if (PyObject_GetBuffer(array, view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0)) < 0) {
        if (!PyErr_ExceptionMatches(PyExc_BufferError) && !PyErr_ExceptionMatches(PyExc_TypeError) &&
            !PyErr_ExceptionMatches(PyExc_ValueError))
            return -1;
        PyErr_Clear();
        return 0;
    }
    if (view->itemsize != 8 || view->format == NULL || strcmp(view->format, "d") != 0 ||
        (count >= 0 && view->len != count * 8)) {
        PyBuffer_Release(view);
        return 0;
    }
    return 1;
}

/* numpy.expm1 of one float, as numpy computes it (its own loop may not be the C library's). */
static int numpy_expm1(double v, double *out) {
    PyObject *arg = PyFloat_FromDouble(v);
    PyObject *value = arg ? PyObject_CallOneArg(NP_EXPM1, arg) : NULL;
    Py_XDECREF(arg);
    if (value == NULL)
        return -1;
    *out = PyFloat_AsDouble(value);
    Py_DECREF(value);
    return *out == -1.0 && PyErr_Occurred() ? -1 : 0;
}

/* advance(x, q, u, x_out, q_out, k3, tau): World._propagate's step by tau > 0, into x_out (q_out):
 * x + tau * u (single integrators, q and q_out None), else closed_form.advance_double with a scalar
 * tau (statexixjd, stateqiqj): z = k3 tau, a = -expm1(-z), b = z + expm1(-z) or its series below
 * SERIES_LIMIT (z_minus_one_plus_exp), q' = (1 - a) q + (a / k3) u, x' = x + (a / k3) q + (b / k3^2) u,
 * element by element in numpy's order. True when done; False, with nothing written, where an array is
 * not a C-contiguous float64 one of x's size (numpy then does it). */
static PyObject *world_advance(PyObject *self, PyObject *args) {
    (void)self;
    PyObject *x_obj, *q_obj, *u_obj, *xo_obj, *qo_obj;
    double k3, tau;
    if (!PyArg_ParseTuple(args, "OOOOOdd", &x_obj, &q_obj, &u_obj, &xo_obj, &qo_obj, &k3, &tau))
        return NULL;
    int single = q_obj == Py_None;
    if (single != (qo_obj == Py_None)) {
        PyErr_SetString(PyExc_TypeError, "advance: q and q_out must both be arrays or both None");
        return NULL;
    }
    if (!single && NP_EXPM1 == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "_fastcore.configure_world was not called");
        return NULL;
    }
    Py_buffer views[5];
    PyObject *objs[5] = {x_obj, u_obj, xo_obj, q_obj, qo_obj};
    int writable[5] = {0, 0, 1, 0, 1}, taken = 0, status = 1;
    for (; taken < (single ? 3 : 5); taken++) {
        status = world_buffer(objs[taken], taken == 0 ? -1 : views[0].len / 8, writable[taken], &views[taken]);
        if (status != 1)
            break;
    }
    double a = 0.0, b = 0.0;
    if (status == 1 && !single) {
        double z = k3 * tau, em, acc = WORLD_SERIES[N_WORLD_SERIES - 1];
        status = numpy_expm1(-z, &em) < 0 ? -1 : 1;
        a = -em;       /* one_minus_exp */
        b = z + em;    /* z_minus_one_plus_exp */
        if (fabs(z) < WORLD_SERIES_LIMIT) {
            for (int k = N_WORLD_SERIES - 2; k >= 0; k--)
                acc = WORLD_SERIES[k] - z * acc;
            b = z * z * acc;
        }
    }
    if (status == 1) {
        const double *x = views[0].buf, *u = views[1].buf;
        double *xo = views[2].buf;
        Py_ssize_t count = views[0].len / 8;
        if (single) {
            for (Py_ssize_t i = 0; i < count; i++)
                xo[i] = x[i] + tau * u[i];
        } else {
            const double *q = views[3].buf;
            double *qo = views[4].buf, keep = 1.0 - a, gain = a / k3, drive = b / (k3 * k3);
            for (Py_ssize_t i = 0; i < count; i++) {
                double qi = q[i];
                xo[i] = x[i] + gain * qi + drive * u[i];
                qo[i] = keep * qi + gain * u[i];
            }
        }
    }
    for (int i = 0; i < taken; i++)
        PyBuffer_Release(&views[i]);
    if (status < 0)
        return NULL;
    return PyBool_FromLong(status);
}

/* abs_max(array): float(numpy.abs(array).max()) of a non-empty C-contiguous float64 array (NaN if it
 * holds one, as numpy's max); None where it is not one (numpy then does it). */
static PyObject *abs_max(PyObject *self, PyObject *array) {
    (void)self;
    Py_buffer view;
    int status = world_buffer(array, -1, 0, &view);
    if (status <= 0)
        return status < 0 ? NULL : Py_NewRef(Py_None);
    const double *v = view.buf;
    Py_ssize_t count = view.len / 8;
    if (count == 0) {
        PyBuffer_Release(&view);
        Py_RETURN_NONE;
    }
    double top = fabs(v[0]);
    for (Py_ssize_t i = 0; i < count && !isnan(top); i++) {
        double a = fabs(v[i]);
        if (isnan(a) || a > top)
            top = a;
    }
    PyBuffer_Release(&view);
    return PyFloat_FromDouble(top);
}

/* A C-contiguous buffer of 8-byte integers (numpy's intp/int64); 0 without an error set otherwise. */
static int index_buffer(PyObject *array, Py_buffer *view) {
    if (PyObject_GetBuffer(array, view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) {
        PyErr_Clear();
        return 0;
    }
    const char *f = view->format;
    if (view->itemsize != 8 || f == NULL || (strcmp(f, "l") != 0 && strcmp(f, "q") != 0)) {
        PyBuffer_Release(view);
        return 0;
    }
    return 1;
}

/* watch_edges(x, rows, start, incident, heads, tails, squared): EdgeLengths.add_edges over the edges with
 * an end at one of `rows` (x's agent rows; `incident[start[k]:start[k + 1]]` the edges of row k): each
 * such edge's squared length ||x_head - x_tail||^2 summed as samples.squared_lengths sums it (left to right,
 * p < 8), kept where it exceeds squared[edge] (numpy.maximum: a NaN stays). An edge met twice is taken
 * twice, to the same float. True when done; False, with nothing written, where the compiled pass cannot
 * take the arrays (numpy then does it). */
static PyObject *watch_edges(PyObject *self, PyObject *args) {
    (void)self;
    PyObject *x_obj, *rows, *objs[4], *sq_obj;
    if (!PyArg_ParseTuple(args, "OO!OOOOO", &x_obj, &PyList_Type, &rows, &objs[0], &objs[1], &objs[2], &objs[3],
                          &sq_obj))
        return NULL;
    Py_buffer xv, sv, iv[4];
    int taken = 0, status = world_buffer(x_obj, -1, 0, &xv);
    if (status != 1)
        return status < 0 ? NULL : Py_NewRef(Py_False);
    status = world_buffer(sq_obj, -1, 1, &sv);
    if (status != 1) {
        PyBuffer_Release(&xv);
        return status < 0 ? NULL : Py_NewRef(Py_False);
    }
    for (; status == 1 && taken < 4; taken++)
        if (!index_buffer(objs[taken], &iv[taken]))
            status = 0;
    if (status == 0)
        taken--; /* the one that failed holds no buffer */
    Py_ssize_t p = 0, n = 0, agents = 0, edges = sv.len / 8;
    if (status == 1) {
        agents = iv[0].len / 8 - 1;
        p = xv.ndim == 2 ? xv.shape[1] : 0;
        n = xv.ndim == 2 ? xv.shape[0] : 0;
        status = p >= 1 && p < 8 && n == agents && iv[2].len / 8 == edges && iv[3].len / 8 == edges;
    }
    const double *x = xv.buf;
    double *squared = sv.buf;
    const long long *start = status ? iv[0].buf : NULL, *incident = status ? iv[1].buf : NULL,
                    *heads = status ? iv[2].buf : NULL, *tails = status ? iv[3].buf : NULL;
    /* checked before anything is written: every index in range */
    for (Py_ssize_t r = 0; status == 1 && r < PyList_GET_SIZE(rows); r++) {
        Py_ssize_t a = PyLong_AsSsize_t(PyList_GET_ITEM(rows, r));
        if (a == -1 && PyErr_Occurred())
            status = -1;
        else if (a < 0 || a >= agents || start[a] < 0 || start[a] > start[a + 1] || start[a + 1] > iv[1].len / 8)
            status = 0;
        for (long long k = status == 1 ? start[a] : 0; status == 1 && k < start[a + 1]; k++) {
            long long e = incident[k];
            status = e >= 0 && e < edges && heads[e] >= 0 && heads[e] < n && tails[e] >= 0 && tails[e] < n;
        }
    }
    for (Py_ssize_t r = 0; status == 1 && r < PyList_GET_SIZE(rows); r++) {
        Py_ssize_t a = PyLong_AsSsize_t(PyList_GET_ITEM(rows, r));
        for (long long k = start[a]; k < start[a + 1]; k++) {
            long long e = incident[k];
            const double *head = x + heads[e] * p, *tail = x + tails[e] * p;
            double total = 0.0;
            for (Py_ssize_t c = 0; c < p; c++) {
                double d = head[c] - tail[c];
                d *= d;
                total = c == 0 ? d : total + d;
            }
            if (!isnan(squared[e]) && (isnan(total) || total > squared[e]))
                squared[e] = total; /* numpy.maximum */
        }
    }
    for (int i = 0; i < taken; i++)
        PyBuffer_Release(&iv[i]);
    PyBuffer_Release(&xv);
    PyBuffer_Release(&sv);
    if (status < 0)
        return NULL;
    return PyBool_FromLong(status);
}

static PyMethodDef methods[] = {
    {"configure", (PyCFunction)(void (*)(void))configure, METH_VARARGS | METH_KEYWORDS,
     "configure(*, growth, max_steps, rtol, gap_fraction, series_limit, series, raiser): the search's "
     "constants and the function that raises the Python path's errors."},
    {"receive", receive, METH_VARARGS,
     "receive(agent, info): the agent's receive for a plain-float agent; False (nothing changed): the "
     "Python path takes it."},
    {"trigger", trigger, METH_VARARGS,
     "trigger(agent, t, sensed): the agent's trigger for a plain-float agent without the safety layer; its "
     "TriggerOutput, or None (nothing changed): the Python path takes it."},
    {"configure_world", (PyCFunction)(void (*)(void))configure_world, METH_VARARGS | METH_KEYWORDS,
     "configure_world(*, expm1, series, series_limit): numpy.expm1 and closed_form's series, for advance."},
    {"advance", world_advance, METH_VARARGS,
     "advance(x, q, u, x_out, q_out, k3, tau): the world's closed-form step by tau into x_out (q_out); False "
     "where an array is not a C-contiguous float64 one (numpy then does it)."},
    {"watch_edges", watch_edges, METH_VARARGS,
     "watch_edges(x, rows, start, incident, heads, tails, squared): EdgeLengths.add_edges for the edges of "
     "these agent rows; False where numpy must do it."},
    {"abs_max", abs_max, METH_O, "abs_max(array): float(numpy.abs(array).max()); None where numpy must do it."},
    {"team_edges", team_edges, METH_VARARGS,
     "team_edges(agents, ids): (neighbours, back) for Team: each agent's neighbours by their position in ids "
     "and its slot among each neighbour's neighbour_ids; None where a neighbour does not list it back."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_fastcore", "The compiled certified first-crossing search (docs/COMPILED_CORE.md).", -1,
    methods, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__fastcore(void) {
    for (int i = 0; i < N_NAMES; i++) {
        NAMES[i] = PyUnicode_InternFromString(NAME_TEXT[i]);
        if (NAMES[i] == NULL)
            return NULL;
    }
    if (PyType_Ready(&SearchType) < 0 || PyType_Ready(&AgendaType) < 0 || PyType_Ready(&TeamType) < 0)
        return NULL;
    if (ZERO == NULL && (ZERO = PyFloat_FromDouble(0.0)) == NULL)
        return NULL;
    TRIGGER_SEARCH = PyUnicode_InternFromString("trigger_search");
    ADVANCE = PyUnicode_InternFromString("advance");
    FRONTIER = PyUnicode_InternFromString("frontier");
    if (TRIGGER_SEARCH == NULL || ADVANCE == NULL || FRONTIER == NULL)
        return NULL;
    PyObject *m = PyModule_Create(&module);
    if (m == NULL)
        return NULL;
    if (PyModule_AddObjectRef(m, "Search", (PyObject *)&SearchType) < 0 ||
        PyModule_AddObjectRef(m, "Agenda", (PyObject *)&AgendaType) < 0 ||
        PyModule_AddObjectRef(m, "Team", (PyObject *)&TeamType) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
