/* bench_fem_linear: the implicit FEM step's two linear solvers against the mesh size, on the
   3D metal frame of examples/common/pn_frame.h (steel, E = 200 GPa, exact von Mises energy) refined
   from 5 mm to finer elements.
   Build: cc -std=c99 -O2 bench/bench_fem_linear.c -lm -o bench_fem_linear   (or: make bench-fem)
   Usage: bench_fem_linear [--sizes 5e-3,3.333e-3,...] [--window S] [--max-gflop G] [--one-level]
                           [--out DIR] [--storage]
   --storage: only each solver's storage per size, as a table on stdout (no steps run).
   Per element size h: the first --window seconds (default 0.01: one step of dt 1e-2 s, the
   plate's first contact, the hardest step of the run) with PN_FEM_LINEAR_CHOLESKY and with
   PN_FEM_LINEAR_PCG (and, with --one-level, PCG on the block IC(0) alone, without the coarse
   level); Cholesky is skipped where one factorization would cost more than --max-gflop
   (default 30) GFLOP. Reported: wall seconds per step, Newton iterations per step,
   CG iterations per Newton iteration, each solver's storage, the largest distance between the
   two solvers' final node positions over the mesh's edge (both solve to newton_tol). Writes DIR/bench_fem_linear.md and .csv;
   progress on stderr. */
#define PLASTINET_IMPLEMENTATION
#include "../examples/common/pn_example.h"
#include "../examples/common/pn_frame.h"

#define MAX_SIZES 16

typedef struct lrun {
    int ok, ran;
    double wall, newton, cg;
    long steps;
    pn_real *x;
} lrun;

static void run_solver(double h, double window, pn_fem_linear_solver ls, int one_level, lrun *r, double *sky_mb, double *sky_gflop,
                       double *blk_mb, size_t *nodes, double *edge) {
    pn_frame_desc fd;
    pn_fem_mesh *m;
    pn_pnet net;
    pn_fem_implicit_desc id;
    char why[256];
    long newton = 0, cg = 0;
    double dmin = 1e300, t0;
    pn__fem *s;
    pn_frame_default(&fd, 3);
    fd.h = h;
    if (!pn_frame_create(&fd, &m, &net, why, sizeof why)) {
        fprintf(stderr, "bench_fem_linear: %s\n", why);
        exit(1);
    }
    s = (pn__fem *)m->impl;
    s->one_level = one_level;
    *sky_mb = s->sky_mb, *sky_gflop = s->sky_gflop, *nodes = m->n_nodes, *edge = m->edge_mean;
    *blk_mb = 2.0 * (double)(s->nblk + 2 * m->n_nodes) * 9 * sizeof(pn_real) / 1e6; /* A, L (and the moving plate's row) */
    memset(&id, 0, sizeof id);
    id.linear_solver = ls;
    r->steps = 0;
    t0 = pn_ex_seconds();
    r->ok = pn_frame_advance(m, window, 1, 1e-2, 0.5, &id, &r->steps, &newton, &cg, &dmin);
    r->wall = pn_ex_seconds() - t0;
    if (!r->ok) fprintf(stderr, "bench_fem_linear: h %g: %s\n", h, pn_fem_error(m));
    r->ran = 1;
    r->newton = r->steps ? (double)newton / (double)r->steps : 0;
    r->cg = newton ? (double)cg / (double)newton : 0;
    r->x = (pn_real *)malloc(sizeof(pn_real) * m->n_nodes * 3);
    if (r->x) memcpy(r->x, m->x, sizeof(pn_real) * m->n_nodes * 3);
    pn_fem_destroy(m);
}

int main(int argc, char **argv) {
    double sizes[MAX_SIZES] = {5e-3, 3.333e-3, 2.5e-3, 2e-3, 1.667e-3}, window = 0.01, max_gflop = 30;
    int ns = 5, k, i, one = 0, storage = 0;
    const char *out = "build";
    char path[1024];
    FILE *md, *csv;
    for (k = 1; k < argc; ++k) {
        const char *a = argv[k], *v = k + 1 < argc ? argv[k + 1] : NULL;
        if (!strcmp(a, "--one-level")) {
            one = 1;
            continue;
        }
        if (!strcmp(a, "--storage")) {
            storage = 1;
            continue;
        }
        if (!v) {
            fprintf(stderr, "usage: bench_fem_linear [--sizes H,H,..] [--window S] [--max-gflop G] [--one-level] [--out DIR]\n");
            return 2;
        }
        ++k;
        if (!strcmp(a, "--out")) out = v;
        else if (!strcmp(a, "--sizes")) {
            char *end;
            const char *p = v;
            for (ns = 0; *p && ns < MAX_SIZES; ++ns) {
                sizes[ns] = strtod(p, &end);
                if (end == p || !(sizes[ns] > 0)) {
                    fprintf(stderr, "bench_fem_linear: bad --sizes '%s'\n", v);
                    return 2;
                }
                p = *end == ',' ? end + 1 : end;
            }
        } else if (!pn_ex_number("bench_fem_linear", a, v, !strcmp(a, "--window") ? &window : &max_gflop) ||
                   (strcmp(a, "--window") && strcmp(a, "--max-gflop"))) {
            fprintf(stderr, "bench_fem_linear: unknown flag '%s'\n", a);
            return 2;
        }
    }
    if (storage) { /* the skyline's estimate, and PCG's arrays as its first step allocates them */
        printf("| h (mm) | nodes | unknowns | Cholesky storage (MB) | GFLOP per factorization | PCG: blocks of A and L (MB) | "
               "coarse level (MB) |\n|---|---|---|---|---|---|---|\n");
        for (i = 0; i < ns; ++i) {
            pn_frame_desc fd;
            pn_fem_mesh *m;
            pn_pnet net;
            char why[256];
            pn__fem *s;
            pn_frame_default(&fd, 3);
            fd.h = sizes[i];
            if (!pn_frame_create(&fd, &m, &net, why, sizeof why) || pn__fem_linear_setup(m, PN_FEM_LINEAR_PCG) != PN_OK) {
                fprintf(stderr, "bench_fem_linear: h %g: %s\n", sizes[i], why);
                return 1;
            }
            s = (pn__fem *)m->impl;
            printf("| %.3g | %lu | %lu | %.0f | %.2f | %.1f | %.1f |\n", sizes[i] * 1e3, (unsigned long)m->n_nodes,
                   (unsigned long)m->n_nodes * 3, s->sky_mb, s->sky_gflop, 2.0 * (double)s->bcap * 9 * sizeof(pn_real) / 1e6,
                   (double)(s->crs[s->cnc] + s->cnc + m->n_nodes * 18) * sizeof(pn_real) / 1e6);
            pn_fem_destroy(m);
        }
        return 0;
    }
    if (!pn_ex_mkdirs(out)) return 1;
    snprintf(path, sizeof path, "%s/bench_fem_linear.md", out);
    md = fopen(path, "w");
    snprintf(path, sizeof path, "%s/bench_fem_linear.csv", out);
    csv = fopen(path, "w");
    if (!md || !csv) {
        fprintf(stderr, "bench_fem_linear: cannot write in %s\n", out);
        return 1;
    }
    fprintf(md, "<!-- written by bench/bench_fem_linear.c (make bench-fem) -->\n"
                "**Linear solvers of the implicit FEM step** against the mesh size: the 3D metal frame (examples/common/pn_frame.h), "
                "steel at 200 GPa, exact von Mises energy, dt 1e-2 s, the first %g s (the plate's first contact). Cholesky: "
                "skyline in reverse Cuthill-McKee order; PCG: conjugate gradients preconditioned by a two-grid cycle (block IC(0) smoothing, "
                "a coarse level of rigid motions of node aggregates); *one level*: block IC(0) alone. *Storage*: the solver's "
                "matrices. *Apart*: the largest distance between the two solvers' final nodes over the mean edge. Cholesky is "
                "not run where a factorization would cost more than %g GFLOP.\n\n"
                "| h (mm) | nodes | unknowns | Cholesky storage (MB) | GFLOP per factorization | PCG storage (MB) | "
                "Cholesky s / step | Newton / step | PCG s / step | Newton / step | CG / Newton | PCG / Cholesky time | apart |"
                "%s\n|---|---|---|---|---|---|---|---|---|---|---|---|---|%s\n",
            window, max_gflop, one ? " one level: s / step | Newton / step | CG / Newton |" : "", one ? "---|---|---|" : "");
    fprintf(csv, "h_m,nodes,unknowns,chol_mb,chol_gflop,pcg_mb,chol_s_per_step,chol_newton,pcg_s_per_step,pcg_newton,"
                 "pcg_cg_per_newton,apart_over_edge\n");
    for (i = 0; i < ns; ++i) {
        lrun ch, pc, o1;
        double mb, gf, bmb, edge, apart = -1;
        size_t nodes, q;
        memset(&ch, 0, sizeof ch);
        memset(&pc, 0, sizeof pc);
        memset(&o1, 0, sizeof o1);
        fprintf(stderr, "h %g: PCG ...\n", sizes[i]);
        run_solver(sizes[i], window, PN_FEM_LINEAR_PCG, 0, &pc, &mb, &gf, &bmb, &nodes, &edge);
        fprintf(stderr, "  %.1f s per step, Newton %.1f, CG %.1f\n", pc.wall / (double)(pc.steps ? pc.steps : 1), pc.newton, pc.cg);
        if (gf <= max_gflop) {
            fprintf(stderr, "h %g: Cholesky ...\n", sizes[i]);
            run_solver(sizes[i], window, PN_FEM_LINEAR_CHOLESKY, 0, &ch, &mb, &gf, &bmb, &nodes, &edge);
            fprintf(stderr, "  %.1f s per step, Newton %.1f\n", ch.wall / (double)(ch.steps ? ch.steps : 1), ch.newton);
            if (ch.x && pc.x)
                for (apart = 0, q = 0; q < nodes * 3; q += 3) {
                    double dx = ch.x[q] - pc.x[q], dy = ch.x[q + 1] - pc.x[q + 1], dz = ch.x[q + 2] - pc.x[q + 2];
                    apart = fmax(apart, sqrt(dx * dx + dy * dy + dz * dz) / edge);
                }
        }
        fprintf(md, "| %.3g | %lu | %lu | %.0f | %.2f | %.1f | ", sizes[i] * 1e3, (unsigned long)nodes, (unsigned long)nodes * 3, mb,
                gf, bmb);
        if (ch.ran) fprintf(md, "%s%.3g | %.1f | ", ch.ok ? "" : "failed: ", ch.wall / (double)(ch.steps ? ch.steps : 1), ch.newton);
        else fprintf(md, "not run | - | ");
        fprintf(md, "%s%.3g | %.1f | %.0f | ", pc.ok ? "" : "failed: ", pc.wall / (double)(pc.steps ? pc.steps : 1), pc.newton, pc.cg);
        if (ch.ran) fprintf(md, "%.2f | %.1e |", pc.wall / ch.wall, apart);
        else fprintf(md, "- | - |");
        if (one) {
            fprintf(stderr, "h %g: PCG, one level ...\n", sizes[i]);
            run_solver(sizes[i], window, PN_FEM_LINEAR_PCG, 1, &o1, &mb, &gf, &bmb, &nodes, &edge);
            fprintf(md, " %s%.3g | %.1f | %.0f |", o1.ok ? "" : "failed: ", o1.wall / (double)(o1.steps ? o1.steps : 1), o1.newton, o1.cg);
        }
        fprintf(md, "\n");
        fprintf(csv, "%g,%lu,%lu,%.1f,%.3f,%.2f,%g,%g,%g,%g,%g,%g\n", sizes[i], (unsigned long)nodes, (unsigned long)nodes * 3, mb, gf,
                bmb, ch.ran ? ch.wall / (double)(ch.steps ? ch.steps : 1) : -1, ch.newton,
                pc.wall / (double)(pc.steps ? pc.steps : 1), pc.newton, pc.cg, apart);
        fflush(md), fflush(csv);
        free(ch.x), free(pc.x), free(o1.x);
    }
    fclose(md), fclose(csv);
    fprintf(stderr, "wrote %s/bench_fem_linear.{md,csv}\n", out);
    return 0;
}
