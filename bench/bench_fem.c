/* bench_fem: where implicit integration pays in FEM, on the metal frame of examples/common/pn_frame.h
   (a steel frame crushed by a plate; plastinet_mpm.h >>fem).
   Build: cc -std=c99 -O2 bench/bench_fem.c -lm -o bench_fem        (or: make bench-fem)
   Usage: bench_fem [--dim 2|3] [--soft-E PA] [--window S] [--out DIR] [--ref-cache DIR]
                    [--no-check] [--quick]
   In one run, per dimension (2D unless --dim 3):
   1. accuracy at a softened stiffness (--soft-E, 2e9 Pa in 2D, 2e8 in 3D), where a converged
      explicit run is affordable: the explicit reference at half the step bound
      (pn_fem_stable_dt) of each step, and the same at the whole bound (how far doubling the
      reference's step moves it bounds how converged it is); implicit at dt
      1e-3, 1e-2 and 1e-1 s with each energy (exact, pnet, lagged: StVK-Hencky + von Mises;
      pnet_nh, nh: Neo-Hookean + von Mises, against their own explicit reference, which
      return-maps by root finding). Error: the mean over frames and nodes of the nodal
      position error over the frame's rest bounding-box diagonal. Frames every 0.02 s over
      0.2 s (the plate at 0.36 m/s goes 40% of the height down); a run at dt 1e-1 s is
      compared at the frames its steps land on (0.1 and 0.2 s);
   2. speed at the real stiffness (E = 200 GPa): the fair explicit baseline at the largest
      fraction of the step bound (4, 2, 1, 0.5) that stays finite over the first --window
      seconds (default 0.01 s), timed over that window and scaled to the whole run (stated
      in the table), against implicit at dt 1e-2 s over the whole run.
   Writes DIR/bench_fem_Nd.csv, .md and .svg (error against wall time; N the dimension);
   progress on stderr. --quick: 2D, coarse (5 mm), short (0.04 s), for a smoke test.
   --ref-cache DIR: keep the references' frames in DIR and read them on a rerun; --no-check:
   skip the reference's convergence check; --energies, --dts: only these implicit runs (comma
   lists); --no-speed: the accuracy part only; --passes N: F0 fixed-point passes of the implicit
   steps (pn_fem_implicit_desc.fixed_point_iters; lagged and PlasticityNet) [1]; --solver: the
   implicit steps' linear solver (pn_fem_implicit_desc.linear_solver) [the default]; --yield R:
   the frame's yield stress over E [3e-3] (pnet and pnet_nh serve 3e-3 only, pnet_nh_any its
   range: they are left out elsewhere); --order 2: quadratic elements on the same cells, the
   reference too. */
#define PLASTINET_IMPLEMENTATION
#include "../examples/common/pn_example.h"
#include "../examples/common/pn_frame.h"

#define FRAME_DT 0.02
#define MAX_FRAMES 64

typedef struct run {
    const char *role;      /* reference, ref_check, implicit, fair, implicit_real */
    int energy, implicit, ok;
    double dt, E, courant;
    int order;             /* 1 linear, 2 quadratic elements                              */
    double err_mean, err_max, wall, sim, newton, dmin, hmax;
    long steps;
} run;

typedef struct cfg {
    int dim, quick, no_check, no_speed, passes, order, ref_order;
    unsigned orders;             /* --orders: the implicit runs' element orders (bit 1, 2)    */
    double ref_dt;               /* --ref-dt: the reference implicit (exact) at this step [0:
                                    explicit]                                              */
    pn_fem_linear_solver solver; /* --solver: the implicit steps' (0: the default)          */
    unsigned energies, dts;      /* the implicit energies (bit PN_FRAME_*) and steps (bit of dts[]) run */
    double soft_E, window, T, speed, h, yield;
    const char *out, *ref_cache, *only;
} cfg;

static void scene(const cfg *c, int energy, double E, int order, pn_frame_desc *d) {
    pn_frame_default(d, c->dim);
    d->energy = energy, d->E = E, d->speed = c->speed, d->yield_ratio = c->yield, d->order = order;
    if (c->h > 0) d->h = c->h;
}

/* One run to time T, recording the node positions at each frame (traj, frames x nodes x dim)
   or comparing them with ref (ref_nd reals a frame: a quadratic reference's first nodes are a
   linear run's); stop after max_sim simulated seconds if > 0. */
static void run_one(const cfg *c, run *r, double *traj, const double *ref, size_t ref_nd, double max_sim) {
    pn_frame_desc d;
    pn_fem_mesh *m = NULL;
    pn_fem_implicit_desc id;
    pn_pnet net;
    char why[256];
    int f, nf = (int)floor(c->T / FRAME_DT + 0.5), compared = 0;
    double sum = 0, diag = 0, t0;
    size_t nd, k;
    r->ok = 1, r->err_mean = r->err_max = r->wall = r->sim = r->newton = r->hmax = 0, r->steps = 0, r->dmin = 1e300;
    memset(&id, 0, sizeof id);
    id.fixed_point_iters = c->passes, id.linear_solver = c->solver;
    scene(c, r->energy, r->E, r->order, &d);
    if (!pn_frame_create(&d, &m, &net, why, sizeof why)) {
        fprintf(stderr, "bench_fem: %s\n", why);
        exit(1);
    }
    diag = sqrt(d.width * d.width + d.height * d.height + (c->dim == 3 ? d.depth * d.depth : 0));
    nd = m->n_nodes * (size_t)c->dim;
    for (f = 1; f <= nf; ++f) {
        double t = f * FRAME_DT;
        long newton = 0;
        if (r->implicit && fmod(t + 1e-9, r->dt) > 1e-6) continue; /* not a frame this run's steps land on */
        if (max_sim > 0 && t > max_sim + 1e-9) t = max_sim;
        t0 = pn_ex_seconds();
        if (!pn_frame_advance(m, t, r->implicit, r->implicit ? r->dt : 1.0, r->courant, &id, &r->steps, &newton, NULL,
                              &r->dmin)) {
            r->wall += pn_ex_seconds() - t0;
            fprintf(stderr, "  %s %s dt %g: failed at t = %g s: %s\n", r->role, pn_frame_energy_names[r->energy], r->dt,
                    (double)m->time_s, pn_fem_error(m));
            r->ok = 0;
            break;
        }
        r->wall += pn_ex_seconds() - t0;
        r->newton += (double)newton;
        r->sim = (double)m->time_s;
        for (k = 0; k < m->n_points; ++k) r->hmax = fmax(r->hmax, (double)m->h[k]);
        if (traj)
            for (k = 0; k < nd; ++k) traj[(size_t)(f - 1) * nd + k] = (double)m->x[k];
        if (ref) {
            double s = 0, mx = 0;
            for (k = 0; k < m->n_nodes; ++k) {
                double e2 = 0;
                int i;
                for (i = 0; i < c->dim; ++i) {
                    double dx = (double)m->x[k * (size_t)c->dim + (size_t)i] - ref[(size_t)(f - 1) * ref_nd + k * (size_t)c->dim + (size_t)i];
                    e2 += dx * dx;
                }
                s += sqrt(e2);
                mx = fmax(mx, sqrt(e2));
            }
            sum += s / (double)m->n_nodes / diag;
            r->err_max = fmax(r->err_max, mx / diag);
            compared++;
        }
        if (max_sim > 0 && t >= max_sim - 1e-12) break;
    }
    if (compared) r->err_mean = sum / compared;
    if (r->steps) r->newton /= (double)r->steps;
    pn_fem_destroy(m);
}

/* --ref-cache DIR: the reference's frames kept in a file per material family, dimension, E,
   duration and element size (a rerun or another session reads them instead of 10 minutes of
   explicit steps) */
static void ref_path(const cfg *c, int fam, char *path, size_t cap) {
    char y[32] = "";
    if (c->yield != 3e-3) snprintf(y, sizeof y, "_Y%g", c->yield); /* the default's name is the older runs' */
    if (c->ref_order == 2) snprintf(y + strlen(y), sizeof y - strlen(y), "_o2");
    if (c->ref_dt > 0) snprintf(y + strlen(y), sizeof y - strlen(y), "_dt%g", c->ref_dt);
    snprintf(path, cap, "%s/bench_fem_ref_%dd_%s_E%g_T%g_h%g%s.bin", c->ref_cache, c->dim, fam ? "nh" : "vm", c->soft_E, c->T,
             c->h > 0 ? c->h : (c->dim == 3 ? 5e-3 : 2.5e-3), y);
}
static int ref_load(const cfg *c, int fam, double *ref, size_t nd, run *r) {
    char path[1024];
    FILE *f;
    double head[6];
    size_t nf = (size_t)floor(c->T / FRAME_DT + 0.5);
    int ok;
    if (!c->ref_cache) return 0;
    ref_path(c, fam, path, sizeof path);
    if (!(f = fopen(path, "rb"))) return 0;
    ok = fread(head, sizeof head, 1, f) == 1 && head[0] == (double)nd && head[1] == (double)nf &&
         fread(ref, sizeof(double), nd * nf, f) == nd * nf;
    fclose(f);
    if (ok) r->ok = 1, r->wall = head[2], r->sim = head[3], r->dmin = head[4], r->hmax = head[5];
    if (ok) fprintf(stderr, "  (reference read from %s)\n", path);
    return ok;
}
static void ref_save(const cfg *c, int fam, const double *ref, size_t nd, const run *r) {
    char path[1024];
    FILE *f;
    double head[6];
    size_t nf = (size_t)floor(c->T / FRAME_DT + 0.5);
    if (!c->ref_cache || !r->ok) return;
    ref_path(c, fam, path, sizeof path);
    if (!(f = fopen(path, "wb"))) return;
    head[0] = (double)nd, head[1] = (double)nf, head[2] = r->wall, head[3] = r->sim, head[4] = r->dmin, head[5] = r->hmax;
    fwrite(head, sizeof head, 1, f);
    fwrite(ref, sizeof(double), nd * nf, f);
    fclose(f);
}

static void progress(const run *r) {
    fprintf(stderr, "  %-13s %-7s %s E %-7.3g dt %-8.3g courant %-4.3g: error mean %.4f max %.4f, wall %.3g s for %.3g s, Newton %.1f, "
                    "min distance %.3g m, max plastic strain %.3f%s\n",
            r->role, r->implicit ? pn_frame_energy_names[r->energy] : "return", r->order == 2 ? "P2" : "P1", r->E, r->dt, r->courant, r->err_mean, r->err_max,
            r->wall, r->sim, r->newton, r->dmin, r->hmax, r->ok ? "" : " (FAILED)");
}

static void svg(const char *path, const run *runs, int n) {
    FILE *f = fopen(path, "w");
    static const char *col[PN_FRAME_ENERGIES] = {"#111111", "#1f5fbf", "#e07b00", "#2a9d3a", "#b0249a", "#17a2b8"};
    double x0 = 1e300, x1 = 0, y0 = 1e300, y1 = 0;
    int k, W = 640, H = 420;
    if (!f) return;
    for (k = 0; k < n; ++k)
        if (runs[k].implicit && !strcmp(runs[k].role, "implicit") && runs[k].ok && runs[k].err_mean > 0) {
            double x = runs[k].wall / runs[k].sim;
            x0 = fmin(x0, x), x1 = fmax(x1, x), y0 = fmin(y0, runs[k].err_mean), y1 = fmax(y1, runs[k].err_mean);
        }
    if (!(x1 > 0)) x0 = 1, x1 = 10, y0 = 1e-3, y1 = 1e-1;
    x0 = pow(10, floor(log10(x0))), x1 = pow(10, ceil(log10(x1))), y0 = pow(10, floor(log10(y0))), y1 = pow(10, ceil(log10(y1)));
    if (x1 <= x0) x1 = 10 * x0;
    if (y1 <= y0) y1 = 10 * y0;
    fprintf(f, "<svg xmlns='http://www.w3.org/2000/svg' width='%d' height='%d' font-family='sans-serif' font-size='12'>\n"
               "<rect width='100%%' height='100%%' fill='white'/>\n<rect x='70' y='20' width='%d' height='%d' fill='none' stroke='#444'/>\n",
            W, H, W - 100, H - 80);
    fprintf(f, "<text x='%d' y='%d' text-anchor='middle'>wall seconds per simulated second (log)</text>\n", W / 2, H - 20);
    fprintf(f, "<text x='16' y='%d' transform='rotate(-90 16 %d)' text-anchor='middle'>mean nodal error / bbox diagonal (log)</text>\n",
            H / 2, H / 2);
    fprintf(f, "<text x='70' y='%d'>%g</text><text x='%d' y='%d' text-anchor='end'>%g</text>\n", H - 45, x0, W - 30, H - 45, x1);
    fprintf(f, "<text x='66' y='%d' text-anchor='end'>%g</text><text x='66' y='28' text-anchor='end'>%g</text>\n", H - 60, y0, y1);
    fprintf(f, "<line x1='70' x2='%d' y1='%.1f' y2='%.1f' stroke='#c00' stroke-dasharray='4 3'/>"
               "<text x='%d' y='%.1f' fill='#c00' text-anchor='end'>2%%</text>\n",
            W - 30, 20 + (H - 80) * (1 - (log10(0.02) - log10(y0)) / (log10(y1) - log10(y0))),
            20 + (H - 80) * (1 - (log10(0.02) - log10(y0)) / (log10(y1) - log10(y0))), W - 34,
            16 + (H - 80) * (1 - (log10(0.02) - log10(y0)) / (log10(y1) - log10(y0))));
    for (k = 0; k < n; ++k) {
        const run *r = &runs[k];
        double px, py;
        if (!r->implicit || strcmp(r->role, "implicit") || !r->ok || !(r->err_mean > 0)) continue;
        px = 70 + (W - 100) * (log10(r->wall / r->sim) - log10(x0)) / (log10(x1) - log10(x0));
        py = 20 + (H - 80) * (1 - (log10(r->err_mean) - log10(y0)) / (log10(y1) - log10(y0)));
        fprintf(f, "<circle cx='%.1f' cy='%.1f' r='5' fill='%s'/><text x='%.1f' y='%.1f' font-size='10'>%s %g</text>\n", px, py,
                col[r->energy], px + 7, py + 4, pn_frame_energy_names[r->energy], r->dt);
    }
    fprintf(f, "</svg>\n");
    fclose(f);
}

int main(int argc, char **argv) {
    static const double dts[] = {1e-3, 1e-2, 1e-1};
    static const double courants[] = {4, 2, 1, 0.5};
    static run runs[64];
    cfg c;
    int k, n = 0, e, i, dim_arg = 0;
    char path[1024];
    FILE *csv, *md;
    memset(&c, 0, sizeof c);
    c.out = "build", c.window = 0.01, c.T = 0.2, c.speed = 0.36, c.yield = 3e-3;
    for (k = 1; k < argc; ++k) {
        const char *a = argv[k], *v = k + 1 < argc ? argv[k + 1] : NULL;
        if (!strcmp(a, "--quick")) c.quick = 1;
        else if (!strcmp(a, "--no-check")) c.no_check = 1;
        else if (!strcmp(a, "--no-speed")) c.no_speed = 1;
        else if (!v) {
            fprintf(stderr, "usage: bench_fem [--dim 2|3] [--soft-E PA] [--window S] [--out DIR] [--ref-cache DIR] [--no-check] [--quick]\n"
                            "                 [--energies exact,pnet,lagged,pnet_nh,nh,pnet_nh_any] [--dts 1e-3,1e-2,1e-1] [--no-speed]\n"
                            "                 [--passes N] [--solver cholesky|pcg] [--yield R] [--order 1|2]\n");
            return 2;
        } else if (!strcmp(a, "--dim")) dim_arg = atoi(v), ++k;
        else if (!strcmp(a, "--soft-E")) c.soft_E = atof(v), ++k;
        else if (!strcmp(a, "--window")) c.window = atof(v), ++k;
        else if (!strcmp(a, "--out")) c.out = v, ++k;
        else if (!strcmp(a, "--ref-cache")) c.ref_cache = v, ++k;
        else if (!strcmp(a, "--passes")) c.passes = atoi(v), ++k;
        else if (!strcmp(a, "--yield")) c.yield = atof(v), ++k;
        else if (!strcmp(a, "--order")) c.order = atoi(v), ++k;
        else if (!strcmp(a, "--ref-order")) c.ref_order = atoi(v), ++k;
        else if (!strcmp(a, "--ref-dt")) c.ref_dt = atof(v), ++k;
        else if (!strcmp(a, "--orders")) c.orders = (strchr(v, '1') ? 2u : 0u) | (strchr(v, '2') ? 4u : 0u), ++k;
        else if (!strcmp(a, "--solver") && (!strcmp(v, "cholesky") || !strcmp(v, "pcg")))
            c.solver = !strcmp(v, "pcg") ? PN_FEM_LINEAR_PCG : PN_FEM_LINEAR_CHOLESKY, ++k;
        else if (!strcmp(a, "--energies") || !strcmp(a, "--dts")) { /* comma lists */
            int is_e = a[2] == 'e', count = is_e ? PN_FRAME_ENERGIES : 3, j;
            unsigned mask = 0;
            char buf[256], *tok;
            snprintf(buf, sizeof buf, "%s", v);
            for (tok = strtok(buf, ","); tok; tok = strtok(NULL, ",")) {
                for (j = 0; j < count; ++j)
                    if (is_e ? !strcmp(tok, pn_frame_energy_names[j]) : fabs(atof(tok) - dts[j]) < 1e-12) break;
                if (j == count) {
                    fprintf(stderr, "bench_fem: %s: unknown entry '%s'\n", a, tok);
                    return 2;
                }
                mask |= 1u << j;
            }
            if (is_e) c.energies = mask;
            else c.dts = mask;
            ++k;
        } else {
            fprintf(stderr, "usage: bench_fem [--dim 2|3] [--soft-E PA] [--window S] [--out DIR] [--ref-cache DIR] [--no-check] [--quick]\n"
                            "                 [--energies exact,pnet,lagged,pnet_nh,nh,pnet_nh_any] [--dts 1e-3,1e-2,1e-1] [--no-speed]\n"
                            "                 [--passes N] [--solver cholesky|pcg] [--yield R] [--order 1|2]\n");
            return 2;
        }
    }
    c.dim = dim_arg ? dim_arg : 2;
    if ((c.dim != 2 && c.dim != 3) || c.soft_E < 0 || !(c.window > 0) || !(c.yield > 0) || c.order < 0 || c.order > 2 ||
        c.ref_order < 0 || c.ref_order > 2 || !(c.ref_dt >= 0)) {
        fprintf(stderr, "bench_fem: bad --dim, --soft-E, --window, --yield, --order, --ref-order or --ref-dt\n");
        return 2;
    }
    if (!c.order) c.order = 1;
    if (!c.ref_order) c.ref_order = c.order;
    if (!c.orders) c.orders = 1u << c.order;
    if ((c.orders & 4u) && c.ref_order != 2) {
        fprintf(stderr, "bench_fem: quadratic runs need a quadratic reference (--ref-order 2)\n");
        return 2;
    }
    if (!c.soft_E) c.soft_E = c.dim == 2 ? 2e9 : 2e8;
    if (!c.energies) c.energies = (1u << PN_FRAME_ENERGIES) - 1;
    if (c.yield != 3e-3) c.energies &= ~(1u << PN_FRAME_PNET | 1u << PN_FRAME_PNET_NH); /* single-material models */
    if (!c.dts) c.dts = 7;
    if (c.quick) c.T = 0.04, c.h = 5e-3, c.window = 1e-3;
    if (!pn_ex_mkdirs(c.out)) return 1;
    fprintf(stderr, "bench_fem %dD: the metal frame, plate %g m/s for %g s, yield stress %g E\n", c.dim, c.speed, c.T, c.yield);
    { /* 1. accuracy at the soft stiffness: per material family, its reference and the implicit runs */
        int fam;
        for (fam = 0; fam < 2; ++fam) {
            static const int fam_energies[2][3] = {{PN_FRAME_EXACT, PN_FRAME_PNET, PN_FRAME_LAGGED},
                                                   {PN_FRAME_PNET_NH, PN_FRAME_NH, PN_FRAME_PNET_NH_ANY}};
            int ref_energy = fam == 0 ? PN_FRAME_EXACT : PN_FRAME_NH, any = 0;
            pn_frame_desc d;
            pn_fem_mesh *m;
            pn_pnet net;
            char why[256];
            size_t nd;
            double *ref;
            for (e = 0; e < 3 && fam_energies[fam][e] >= 0; ++e) any |= c.energies >> fam_energies[fam][e] & 1;
            if (!any) continue;
            scene(&c, ref_energy, c.soft_E, c.ref_order, &d);
            if (!pn_frame_create(&d, &m, &net, why, sizeof why)) return 1;
            nd = m->n_nodes * (size_t)c.dim;
            pn_fem_destroy(m);
            ref = (double *)malloc(sizeof(double) * nd * MAX_FRAMES);
            if (!ref) return 1;
            memset(&runs[n], 0, 2 * sizeof runs[0]);
            runs[n].role = "reference", runs[n].energy = ref_energy, runs[n].E = c.soft_E, runs[n].courant = 0.5;
            runs[n].order = c.ref_order, runs[n].implicit = c.ref_dt > 0, runs[n].dt = c.ref_dt;
            if (!ref_load(&c, fam, ref, nd, &runs[n])) {
                run_one(&c, &runs[n], ref, NULL, nd, 0);
                ref_save(&c, fam, ref, nd, &runs[n]);
            }
            progress(&runs[n++]);
            runs[n] = runs[n - 1]; /* the check: the reference at twice its step */
            runs[n].role = "ref_check", runs[n].courant = 1, runs[n].dt = 2 * c.ref_dt;
            if (!c.no_check) { /* --no-check: no row (not a check that passed) */
                run_one(&c, &runs[n], NULL, ref, nd, 0);
                progress(&runs[n++]);
            }
            for (e = 0; e < 3 && fam_energies[fam][e] >= 0; ++e)
                for (i = 0; i < 3 * 2; ++i) {
                    run *r = &runs[n++];
                    memset(r, 0, sizeof *r);
                    r->role = "implicit", r->energy = fam_energies[fam][e], r->E = c.soft_E, r->implicit = 1, r->dt = dts[i % 3];
                    r->order = 1 + i / 3;
                    if ((c.quick && dts[i % 3] > 1e-2) || !(c.energies >> r->energy & 1) || !(c.dts >> (i % 3) & 1) ||
                        !(c.orders >> r->order & 1)) {
                        n--;
                        continue;
                    }
                    run_one(&c, r, NULL, ref, nd, 0);
                    progress(r);
                }
            free(ref);
        }
    }
    { /* 2. speed at 200 GPa: the fair explicit baseline over the window, implicit at 1e-2 s */
        run *best = NULL;
        for (i = 0; i < 4 && !best && !c.no_speed; ++i) {
            run *r = &runs[n];
            memset(r, 0, sizeof *r);
            r->role = "fair", r->energy = PN_FRAME_EXACT, r->E = 2e11, r->courant = courants[i], r->order = c.order;
            run_one(&c, r, NULL, NULL, 0, c.window);
            progress(r);
            n++;
            if (r->ok) best = r;
        }
        for (e = 0; e < PN_FRAME_ENERGIES * 2; ++e) {
            run *r;
            if (c.no_speed || !(c.energies >> (e % PN_FRAME_ENERGIES) & 1) || !(c.orders >> (1 + e / PN_FRAME_ENERGIES) & 1)) continue;
            r = &runs[n++];
            memset(r, 0, sizeof *r);
            r->role = "implicit_real", r->energy = e % PN_FRAME_ENERGIES, r->E = 2e11, r->implicit = 1, r->dt = 1e-2;
            r->order = 1 + e / PN_FRAME_ENERGIES;
            run_one(&c, r, NULL, NULL, 0, 0);
            progress(r);
        }
        snprintf(path, sizeof path, "%s/bench_fem_%dd.csv", c.out, c.dim);
        csv = fopen(path, "w");
        snprintf(path, sizeof path, "%s/bench_fem_%dd.md", c.out, c.dim);
        md = fopen(path, "w");
        if (!csv || !md) return 1;
        fprintf(csv, "dim,role,integrator,energy,E,dt,courant,error_mean,error_max,wall_s,sim_s,wall_per_sim_s,x_fair,newton_per_step,"
                     "min_distance_m,max_plastic_strain,ok,order\n");
        fprintf(md, "<!-- written by bench/bench_fem.c (make bench-fem) -->\n**Metal frame %dD%s** (examples/common/pn_frame.h), yield "
                    "stress %g E: plate at %g m/s for %g s. Error: mean over frames (every %g s) and nodes of the nodal position error over the rest "
                    "bounding-box diagonal (a linear run: its nodes, the corners of a quadratic reference), against the %s "
                    "reference of the same material at E = %g Pa%s. *x fair*: wall time "
                    "per simulated second over the fair explicit baseline's at 200 GPa%s.\n\n",
                c.dim, c.order == 2 ? ", quadratic elements" : "", c.yield, c.speed, c.T, FRAME_DT,
                c.ref_dt > 0 ? "implicit (exact energy)" : "explicit", c.soft_E,
                c.ref_order == 2 ? " on quadratic elements" : "",
                best ? "" : c.no_speed ? " (not measured: --no-speed)" : " (no explicit step fraction stayed finite: no ratio)");
        if (best)
            fprintf(md, "Fair explicit baseline at 200 GPa: %g of pn_fem_stable_dt at each step, timed over the first %g s (%ld "
                        "steps) and scaled to the whole run: %.4g wall s per simulated s.\n\n",
                    best->courant, best->sim, best->steps, best->wall / best->sim);
        fprintf(md, "| role | integrator | elements | energy | E (Pa) | dt (s) | error mean / max | wall s / sim s | x fair | Newton / step | "
                    "min distance (m) | max plastic strain | finite |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
        for (k = 0; k < n; ++k) {
            const run *r = &runs[k];
            double wps = r->sim > 0 ? r->wall / r->sim : 0, xf = best && wps > 0 ? wps / (best->wall / best->sim) : 0;
            char dts_s[32];
            if (r->implicit) snprintf(dts_s, sizeof dts_s, "%g", r->dt);
            else snprintf(dts_s, sizeof dts_s, "%g x bound", r->courant);
            fprintf(csv, "%d,%s,%s,%s,%g,%g,%g,%.6g,%.6g,%.6g,%.6g,%.6g,%.4g,%.3g,%.4g,%.4g,%d,%d\n", c.dim, r->role,
                    r->implicit ? "implicit" : "explicit", r->implicit ? pn_frame_energy_names[r->energy] : "return_mapping", r->E,
                    r->implicit ? r->dt : 0, r->courant, r->err_mean, r->err_max, r->wall, r->sim, wps, xf, r->newton, r->dmin,
                    r->hmax, r->ok, r->order == 2 ? 2 : 1);
            {
                char err_s[48] = "-", xf_s[32] = "-";
                if (strcmp(r->role, "reference") && strcmp(r->role, "fair") && strcmp(r->role, "implicit_real"))
                    snprintf(err_s, sizeof err_s, "%.4f / %.4f", r->err_mean, r->err_max);
                if (xf > 0 && (r == best || !strcmp(r->role, "implicit_real"))) snprintf(xf_s, sizeof xf_s, "%.4f", xf);
                fprintf(md, "| %s | %s | %s | %s | %g | %s | %s | %.4g | %s | %.1f | %.3g | %.3f | %s |\n", r->role,
                        r->implicit ? "implicit" : "explicit", r->order == 2 ? "quadratic" : "linear",
                        r->implicit ? pn_frame_energy_names[r->energy] : "return mapping",
                        r->E, dts_s, err_s, wps, xf_s, r->newton, r->dmin, r->hmax, r->ok ? "yes" : "no");
            }
        }
        fclose(csv);
        fclose(md);
    }
    snprintf(path, sizeof path, "%s/bench_fem_%dd.svg", c.out, c.dim);
    svg(path, runs, n);
    fprintf(stderr, "wrote %s/bench_fem_%dd.{csv,md,svg}\n", c.out, c.dim);
    return 0;
}
