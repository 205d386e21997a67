/* demo.c: the 2D sand / snow sandbox of examples/web/index.html, compiled to WebAssembly by
   emscripten (`make web`; app.js calls the demo_* functions below). Explicit MPM
   (pn_mpm_step_explicit, the analytic return mapping) on a 96 x 60 grid (3 m x 1.875 m), a
   column of 2295 particles (2 x 2 per cell, jittered) that collapses:
     sand  StVK-Hencky + Drucker-Prager, E 1e5 Pa, nu 0.3, friction angle 35 deg, 1600 kg/m^3
     snow  Neo-Hookean snow + Cam-Clay with hardening (nu 0.3, 45 deg, beta 0.3, xi 3),
           E 3e4 Pa, 400 kg/m^3, initial log J_p = -0.06 (the consolidation that gives it
           cohesion: it cracks into blocks)
   Both are far softer than the real materials (sand 1e7-1e8 Pa) so the explicit step, bounded
   by the elastic wave speed c = sqrt((lambda + 2 mu) / rho) (about 9-10 m/s here), stays
   affordable: each frame advances the time the page asks for with pn_mpm_advance, in steps
   of pn_mpm_stable_dt (0.9 dx / max_p (c_p + |v_p|)), about 6 per 1/60 s. Cost: ~1 us per
   particle and step natively, ~1.3 us in WebAssembly (a 2.6 GHz EPYC core).
   A disk collider (SEPARATE contact, Coulomb friction) follows the pointer at a bounded
   speed; pn_mpm_move_collider gives it its real velocity, so it pushes the material rather
   than teleporting through it. It waits high above the box while the pointer is up.
   Native timing run: cc -std=c99 -O2 -DDEMO_MAIN examples/web/demo.c -lm && ./a.out [sand|snow] [frames] */
#define PLASTINET_IMPLEMENTATION
#define PN_NO_FEM /* particles only: FEM and coupling left out of the build */
#include "../../plastinet.h"
#include "../../plastinet_mpm.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#ifdef __EMSCRIPTEN__
#include <emscripten.h>
#else
#define EMSCRIPTEN_KEEPALIVE
#endif

#define RES_X 96           /* grid cells: a 3 m x 1.875 m box                               */
#define RES_Y 60
#define DX (1.0 / 32)      /* m                                                             */
#define WALL 3             /* wall cells; the floor is at WALL * DX                         */
#define RADIUS 0.12        /* collider radius (m)                                           */
#define MAX_PUSH 3.0       /* the collider's top speed (m/s)                                */
#define PARK_Y 10.0        /* where the collider waits when the pointer is up (m)           */

typedef struct demo_state {
    pn_mpm_world *w;
    int kind;              /* 0 sand, 1 snow                                                */
    int collider;          /* its index                                                     */
    double c_m_s;          /* elastic wave speed of the material                            */
    double cx, cy;         /* collider centre now (m)                                       */
    double tx, ty;         /* where the pointer wants it                                    */
    int down;              /* pointer pressed                                               */
    double max_speed, dt;  /* fastest particle after the last frame, its mean step (s)       */
    int substeps, failures;
    float *out;            /* x, y, speed per particle (speed < 0: inactive)                */
    size_t out_cap;
} demo_state;

static demo_state S;

static void demo_park(void) {
    pn_real c[2];
    S.cx = RES_X * DX / 2;
    S.cy = PARK_Y;
    c[0] = (pn_real)S.cx;
    c[1] = (pn_real)S.cy;
    if (S.w) pn_mpm_move_collider(S.w, S.collider, c, NULL);
}

/* Build the scene: a column of material standing on the floor in the middle of the box (it
   collapses into a heap: sand flows, snow holds better). Returns the particle count or < 0. */
EMSCRIPTEN_KEEPALIVE int demo_reset(int kind) {
    pn_mpm_desc wd;
    pn_material_desc md;
    pn_material m;
    pn_collider col;
    char why[256] = "";
    double sp = DX / 2, x0, y0, width = 0.7, height = 0.8, rho;
    int nx = (int)(width / sp + 0.5), ny = (int)(height / sp + 0.5), i, j, g;
    size_t n = (size_t)nx * (size_t)ny, p;
    unsigned int seed = 1;  /* 32 bits on every target we build for */
    pn_real *x;
    pn_result r;
    if (S.w) pn_mpm_destroy(S.w);
    S.w = NULL;
    S.kind = kind ? 1 : 0;
    memset(&md, 0, sizeof md);
    md.poisson_ratio = 0.3;
    if (S.kind == 0) {
        md.plastic = PN_PLASTIC_DRUCKER_PRAGER;
        md.youngs_modulus_pa = 1e5;
        md.friction_angle_deg = 35;
        rho = 1600;
    } else {
        md.plastic = PN_PLASTIC_CAM_CLAY;
        md.youngs_modulus_pa = 3e4;
        md.friction_angle_deg = 45;
        md.camclay_beta = 0.3;
        md.camclay_xi = 3;
        rho = 400;
    }
    if ((r = pn_material_init(&m, &md, why, sizeof why)) != PN_OK) {
        printf("demo: material: %s\n", why);
        return -1;
    }
    S.c_m_s = sqrt((m.lambda + 2 * m.mu) / rho);
    memset(&wd, 0, sizeof wd);
    wd.dim = 2;
    wd.res[0] = RES_X;
    wd.res[1] = RES_Y;
    wd.dx_m = (pn_real)DX;
    wd.gravity[1] = (pn_real)-9.81;
    wd.boundary = PN_BOUNDARY_SEPARATE;
    wd.friction = (pn_real)0.6;
    wd.wall_cells = WALL;
    wd.max_particles = n;
    wd.allow_outflow = 1; /* a particle pushed through a wall is retired, not an error */
    if (pn_mpm_create(&wd, &S.w, why, sizeof why) != PN_OK) {
        printf("demo: world: %s\n", why);
        return -2;
    }
    g = pn_mpm_add_group(S.w, &m, (pn_real)rho);
    x = (pn_real *)malloc(sizeof(pn_real) * 2 * n);
    if (g < 0 || !x) {
        free(x);
        return -3;
    }
    x0 = RES_X * DX / 2 - nx * sp / 2;
    x0 = floor(x0 / sp + 0.5) * sp; /* two particles per cell and axis, at quarter cells */
    y0 = WALL * DX;
    for (p = 0, i = 0; i < nx; ++i)
        for (j = 0; j < ny; ++j, ++p) { /* a random point of each lattice cell: no lattice artefacts */
            seed = seed * 1103515245u + 12345u;
            x[2 * p] = (pn_real)(x0 + (i + 0.1 + 0.8 * (double)(seed >> 16 & 32767) / 32767) * sp);
            seed = seed * 1103515245u + 12345u;
            x[2 * p + 1] = (pn_real)(y0 + (j + 0.1 + 0.8 * (double)(seed >> 16 & 32767) / 32767) * sp);
        }
    r = pn_mpm_add_particles(S.w, g, n, x, NULL, (pn_real)(sp * sp));
    if (r == PN_OK && S.kind == 1) { /* consolidated snow: log J_p < 0 gives it strength */
        for (p = 0; p < n; ++p) x[p] = (pn_real)-0.06;
        r = pn_mpm_set_state(S.w, 0, n, x);
    }
    free(x);
    memset(&col, 0, sizeof col);
    col.shape = PN_SHAPE_SPHERE;
    col.boundary = PN_BOUNDARY_SEPARATE;
    col.friction = (pn_real)0.2;
    col.radius_m = (pn_real)RADIUS;
    col.center_m[0] = (pn_real)(RES_X * DX / 2);
    col.center_m[1] = (pn_real)PARK_Y;
    if (r != PN_OK || pn_mpm_add_collider(S.w, &col, &S.collider) != PN_OK) {
        pn_mpm_destroy(S.w);
        S.w = NULL;
        return -4;
    }
    if (S.out_cap < n) {
        free(S.out);
        S.out = (float *)malloc(sizeof(float) * 3 * n);
        S.out_cap = S.out ? n : 0;
        if (!S.out) return -5;
    }
    S.down = 0;
    S.max_speed = 0;
    S.substeps = 0;
    S.dt = 0;
    demo_park();
    return (int)n;
}

/* The pointer, in metres (x right, y up from the domain's corner). down = 0: released. */
EMSCRIPTEN_KEEPALIVE void demo_pointer(int down, double x, double y) {
    double lo = WALL * DX + RADIUS * 0.5, hx = RES_X * DX - lo, hy = RES_Y * DX - lo;
    if (!S.w) return;
    /* keep the target inside the walls: the collider never pins material against them */
    S.tx = x < lo ? lo : x > hx ? hx : x;
    S.ty = y < lo ? lo : y > hy ? hy : y;
    if (down && !S.down) {
        /* a press: start at the pointer if that is free space; inside material, start above
           it at the top of the box and plough down (a disk that appears inside the material
           would trap particles) */
        size_t p;
        double r2 = (RADIUS + DX) * (RADIUS + DX);
        int free_space = 1;
        for (p = 0; p < S.w->n && free_space; ++p) {
            double ex = S.w->x[2 * p] - S.tx, ey = S.w->x[2 * p + 1] - S.ty;
            if (S.w->active[p] && ex * ex + ey * ey < r2) free_space = 0;
        }
        S.cx = S.tx;
        S.cy = free_space ? S.ty : RES_Y * DX + RADIUS;
    }
    if (!down && S.down) demo_park();
    S.down = down != 0;
}

/* Advance frame_s seconds of simulated time. Returns the substeps taken, < 0 on a failure
   that a smaller step could not fix (the page then resets). */
EMSCRIPTEN_KEEPALIVE int demo_frame(double frame_s) {
    pn_real c[2], v[2];
    pn_mpm_advance_desc ad;
    pn_mpm_stats st;
    pn_result r;
    double vx = 0, vy = 0, t_end;
    int steps;
    if (!S.w || !(frame_s > 0)) return -1;
    if (frame_s > 0.05) frame_s = 0.05;
    t_end = (double)S.w->time_s + frame_s;
    if (S.down) { /* head for the pointer at most MAX_PUSH m/s; contact gets that velocity */
        double ex = S.tx - S.cx, ey = S.ty - S.cy, len = sqrt(ex * ex + ey * ey);
        double lim = MAX_PUSH * frame_s, s = len > lim ? lim / len : 1;
        vx = ex * s / frame_s;
        vy = ey * s / frame_s;
    }
    c[0] = (pn_real)S.cx;
    c[1] = (pn_real)S.cy;
    v[0] = (pn_real)vx;
    v[1] = (pn_real)vy;
    pn_mpm_move_collider(S.w, S.collider, c, v);
    /* pn_mpm_advance: explicit steps at pn_mpm_stable_dt (0.9 dx / max (c_p + |v_p|)), and while
       the collider moves, no longer than it takes to cross that fraction of a cell */
    memset(&ad, 0, sizeof ad);
    ad.integrator = PN_MPM_EXPLICIT;
    if (S.down) ad.max_step_s = (pn_real)(0.9 * DX / (S.c_m_s + MAX_PUSH));
    memset(&st, 0, sizeof st); /* pn_mpm_advance fills it only on success */
    r = pn_mpm_advance(S.w, (pn_real)frame_s, &ad, &st);
    steps = r == PN_OK ? st.substeps : 0;
    if (r != PN_OK) { /* the world is as after the last good step: finish at half the step */
        pn_real left = (pn_real)(t_end - (double)S.w->time_s);
        S.failures++;
        printf("demo: %s; retrying at half the step\n", pn_mpm_error(S.w));
        ad.courant = (pn_real)0.5;
        memset(&st, 0, sizeof st);
        r = left > 0 ? pn_mpm_advance(S.w, left, &ad, &st) : PN_OK;
        if (r != PN_OK) {
            printf("demo: %s\n", pn_mpm_error(S.w));
            return -2;
        }
        steps += left > 0 ? st.substeps : 0;
    }
    S.max_speed = st.max_speed_m_s;
    S.dt = steps > 0 ? frame_s / steps : 0;
    S.cx += vx * frame_s;
    S.cy += vy * frame_s;
    S.substeps = steps;
    return steps;
}

/* Particle count (active or not) and x, y, speed per particle as floats (speed -1: inactive);
   the pointer stays valid until the next demo_reset. */
EMSCRIPTEN_KEEPALIVE int demo_count(void) { return S.w ? (int)S.w->n : 0; }

EMSCRIPTEN_KEEPALIVE float *demo_particles(void) {
    size_t p;
    if (!S.w) return NULL;
    for (p = 0; p < S.w->n; ++p) {
        const pn_real *x = S.w->x + 2 * p, *v = S.w->v + 2 * p;
        S.out[3 * p] = (float)x[0];
        S.out[3 * p + 1] = (float)x[1];
        S.out[3 * p + 2] = S.w->active[p] ? (float)sqrt((double)(v[0] * v[0] + v[1] * v[1])) : -1.0f;
    }
    return S.out;
}

/* Numbers for the page: 0 width, 1 height of the box (m), 2 floor height, 3 and 4 collider
   centre, 5 its radius, 6 fastest particle (m/s), 7 simulated time (s), 8 mean step (s),
   9 steps of the last frame, 10 wave speed (m/s), 11 active particles, 12 frames whose
   pn_mpm_advance failed and was finished at half the step, 13 material (0 sand, 1 snow). */
EMSCRIPTEN_KEEPALIVE double demo_info(int what) {
    size_t p, k = 0;
    switch (what) {
    case 0: return RES_X * DX;
    case 1: return RES_Y * DX;
    case 2: return WALL * DX;
    case 3: return S.cx;
    case 4: return S.cy;
    case 5: return RADIUS;
    case 6: return S.max_speed;
    case 7: return S.w ? (double)S.w->time_s : 0;
    case 8: return S.dt;
    case 9: return S.substeps;
    case 10: return S.c_m_s;
    case 11:
        for (p = 0; S.w && p < S.w->n; ++p) k += S.w->active[p];
        return (double)k;
    case 12: return S.failures;
    case 13: return S.kind;
    default: return 0;
    }
}

#ifdef DEMO_MAIN
#include <time.h>
/* native timing run: the column collapses, then the collider ploughs through it */
int main(int argc, char **argv) {
    int kind = argc > 1 && !strcmp(argv[1], "snow"), frames = argc > 2 ? atoi(argv[2]) : 120, f;
    int n = demo_reset(kind), steps = 0;
    clock_t t0 = clock();
    for (f = 0; f < frames; ++f) {
        int s;
        if (f == frames / 2) demo_pointer(1, 0.3, 0.15);
        if (f > frames / 2) demo_pointer(1, 0.3 + 1.4 * (f - frames / 2) / (frames / 2.0), 0.15);
        s = demo_frame(1.0 / 60);
        if (s < 0) return 1;
        steps += s;
    }
    printf("%s: %d particles, c %.1f m/s, %d frames, %.1f substeps/frame, %.2f ms/frame, "
           "%.3f us/particle-step, max speed %.2f, active %.0f, failures %d\n",
           kind ? "snow" : "sand", n, S.c_m_s, frames, (double)steps / frames,
           1e3 * (double)(clock() - t0) / CLOCKS_PER_SEC / frames,
           1e6 * (double)(clock() - t0) / CLOCKS_PER_SEC / ((double)steps * n), S.max_speed,
           demo_info(11), S.failures);
    return 0;
}
#endif
