/* materials: four materials and two colliders in one 2D world. A heap of sand, a rubber ball
   and a block of snow fall on a floor; a soft steel bar falls across a round post and bends
   (von Mises plasticity); a plate moves in from the left and bulldozes the sand. Every
   material is filled with pn_mpm_fill and stepped with pn_mpm_advance (explicit steps at
   pn_mpm_stable_dt); colours show the material.
   Build: cc -std=c99 -O2 examples/materials.c -lm -o materials
   Usage: materials [--frames N] [--res N] [--out DIR] [--png] [--apng] [--quiet]
   Writes DIR/frame_NNNN.png (--png) and DIR/preview.png (--apng, every second frame) [DIR:
   build/materials_frames]; prints per material its particle count and final centre. */
#define PLASTINET_IMPLEMENTATION
#define PN_NO_FEM /* particles only: FEM and coupling left out of the build */
#include "common/pn_example.h"

enum { SAND, RUBBER, METAL, SNOW, KINDS };
static const char *const names[KINDS] = {"sand", "rubber", "steel", "snow"};

static void usage(FILE *f) {
    fprintf(f, "usage: materials [flags]   four materials and two colliders in a 2D box, explicit steps\n"
               "  --frames N      frames at 30 per second [30]\n"
               "  --res N         grid cells per axis, 32 .. 512 [64]\n"
               "  --out DIR       where frames go (created) [build/materials_frames]\n"
               "  --png  --apng   frames as PNG pictures, one animated PNG of every second frame (DIR/preview.png)\n"
               "  --quiet         no progress line\n"
               "  --help          this text\n");
}

/* material of kind k (E lowered from real values so that explicit steps stay few) */
static int add_group(pn_mpm_world *w, int k) {
    static const double rho[KINDS] = {1600, 1100, 7800, 400};
    pn_material_desc d;
    pn_material m;
    char why[256] = "";
    memset(&d, 0, sizeof d);
    d.poisson_ratio = 0.3;
    switch (k) {
    case SAND:
        d.plastic = PN_PLASTIC_DRUCKER_PRAGER, d.youngs_modulus_pa = 2e6, d.friction_angle_deg = 35;
        break;
    case RUBBER: d.elastic = PN_ELASTIC_NEO_HOOKEAN, d.youngs_modulus_pa = 3e5, d.poisson_ratio = 0.4; break;
    case METAL:
        d.plastic = PN_PLASTIC_VON_MISES, d.youngs_modulus_pa = 1e8, d.yield_stress_pa = 2e5,
        d.hardening_modulus_pa = 1e6;
        break;
    default:
        d.plastic = PN_PLASTIC_CAM_CLAY, d.youngs_modulus_pa = 5e5, d.friction_angle_deg = 45, d.camclay_beta = 0.3,
        d.camclay_xi = 3;
        break;
    }
    if (pn_material_init(&m, &d, why, sizeof why) != PN_OK) {
        fprintf(stderr, "materials: %s\n", why);
        return -1;
    }
    return pn_mpm_add_group(w, &m, rho[k]);
}

int main(int argc, char **argv) {
    pn_mpm_desc wd;
    pn_mpm_world *w = NULL;
    pn_mpm_fill_desc f[KINDS];
    pn_collider post, plate;
    pn_ex_view view;
    pn_apng *anim = NULL;
    unsigned char *rgb = NULL;
    pn_real *color = NULL;
    const char *out = "build/materials_frames";
    char why[256] = "";
    double frames_f = 30, res_f = 64, dx, fl;
    int png = 0, apng = 0, quiet = 0, k, frame, plate_index = -1, i;
    size_t n = 0, cnt, p;
    for (k = 1; k < argc; ++k) {
        const char *a = argv[k], *v = k + 1 < argc ? argv[k + 1] : NULL;
        if (!strcmp(a, "--help") || !strcmp(a, "-h")) return usage(stdout), 0;
        if (!strcmp(a, "--png")) png = 1;
        else if (!strcmp(a, "--apng")) apng = 1;
        else if (!strcmp(a, "--quiet")) quiet = 1;
        else if (!strcmp(a, "--frames") && pn_ex_number("materials", a, v, &frames_f) && frames_f >= 1) ++k;
        else if (!strcmp(a, "--res") && pn_ex_number("materials", a, v, &res_f) && res_f >= 32 && res_f <= 512) ++k;
        else if (!strcmp(a, "--out") && v) out = v, ++k;
        else {
            fprintf(stderr, "materials: bad flag or value '%s' (--help lists them)\n", a);
            return 2;
        }
    }
    dx = 1.0 / (int)res_f;
    fl = 3 * dx; /* the floor: the top of the bottom wall */
    memset(&wd, 0, sizeof wd);
    wd.dim = 2;
    wd.res[0] = wd.res[1] = (int)res_f;
    wd.dx_m = (pn_real)dx;
    wd.gravity[1] = (pn_real)-9.81;
    wd.boundary = PN_BOUNDARY_SEPARATE;
    wd.friction = (pn_real)0.4;
    wd.filter_time_s = (pn_real)2e-3;
    /* the shapes, all on the grid's lattice (2 x 2 particles per cell) */
    memset(f, 0, sizeof f);
    f[SAND].shape = PN_MPM_FILL_BOX; /* a heap on the floor, middle left */
    f[SAND].center_m[0] = (pn_real)0.36, f[SAND].center_m[1] = (pn_real)(fl + 0.09);
    f[SAND].half_extent_m[0] = (pn_real)0.12, f[SAND].half_extent_m[1] = (pn_real)0.09;
    f[RUBBER].shape = PN_MPM_FILL_SPHERE; /* a ball dropped on the heap */
    f[RUBBER].center_m[0] = (pn_real)0.36, f[RUBBER].center_m[1] = (pn_real)0.5;
    f[RUBBER].radius_m = (pn_real)0.06;
    f[METAL].shape = PN_MPM_FILL_BOX; /* a bar above the post */
    f[METAL].center_m[0] = (pn_real)0.74, f[METAL].center_m[1] = (pn_real)0.52;
    f[METAL].half_extent_m[0] = (pn_real)0.16, f[METAL].half_extent_m[1] = (pn_real)0.02;
    f[SNOW].shape = PN_MPM_FILL_CYLINDER; /* a tilted block of snow thrown at the floor */
    f[SNOW].center_m[0] = (pn_real)0.6, f[SNOW].center_m[1] = (pn_real)0.75;
    f[SNOW].axis[0] = 1, f[SNOW].axis[1] = (pn_real)0.5;
    f[SNOW].half_length_m = (pn_real)0.07, f[SNOW].radius_m = (pn_real)0.04;
    f[SNOW].velocity_m_s[0] = (pn_real)-1.5;
    f[SNOW].state = (pn_real)-0.01; /* some consolidation: log J_p */
    for (k = 0; k < KINDS; ++k) {
        f[k].jitter = 1;
        f[k].seed = (unsigned long)k + 1;
        if (pn_mpm_fill_count(&wd, &f[k], &cnt, why, sizeof why) != PN_OK) return fprintf(stderr, "materials: %s\n", why), 1;
        n += cnt;
    }
    wd.max_particles = n;
    if (pn_mpm_create(&wd, &w, why, sizeof why) != PN_OK) return fprintf(stderr, "materials: %s\n", why), 1;
    for (k = 0; k < KINDS; ++k)
        if ((f[k].group = add_group(w, k)) < 0 || pn_mpm_fill(w, &f[k], NULL) != PN_OK) {
            fprintf(stderr, "materials: %s\n", pn_mpm_error(w));
            pn_mpm_destroy(w);
            return 1;
        }
    memset(&post, 0, sizeof post); /* a round post the bar falls across */
    post.shape = PN_SHAPE_SPHERE;
    post.boundary = PN_BOUNDARY_SEPARATE;
    post.friction = (pn_real)0.3;
    post.center_m[0] = (pn_real)0.74, post.center_m[1] = (pn_real)(fl + 0.12);
    post.radius_m = (pn_real)0.05;
    memset(&plate, 0, sizeof plate); /* a plate that comes in from the left at 0.3 m/s */
    plate.shape = PN_SHAPE_BOX;
    plate.boundary = PN_BOUNDARY_SLIP;
    plate.center_m[0] = (pn_real)0.08, plate.center_m[1] = (pn_real)(fl + 0.06);
    plate.half_extent_m[0] = (pn_real)0.02, plate.half_extent_m[1] = (pn_real)0.06;
    plate.velocity_m_s[0] = (pn_real)0.3;
    if (pn_mpm_add_collider(w, &post, NULL) != PN_OK || pn_mpm_add_collider(w, &plate, &plate_index) != PN_OK) {
        fprintf(stderr, "materials: %s\n", pn_mpm_error(w));
        pn_mpm_destroy(w);
        return 1;
    }
    memset(&view, 0, sizeof view);
    view.width = 960, view.height = 540;
    view.hi[0] = 1, view.hi[1] = 9.0 / 16;
    view.floor_m = fl;
    view.title = "sand, rubber, steel, snow";
    if ((png || apng) && !pn_ex_mkdirs(out)) return fprintf(stderr, "materials: cannot create %s\n", out), 1;
    if (png || apng) {
        char path[1024];
        snprintf(path, sizeof path, "%s/preview.png", out);
        rgb = (unsigned char *)malloc((size_t)view.width * (size_t)view.height * 3);
        color = (pn_real *)malloc(sizeof(pn_real) * n);
        if (!rgb || !color || (apng && !(anim = pn_apng_open(path, view.width, view.height, 15)))) {
            fprintf(stderr, "materials: cannot start the pictures\n");
            return 1;
        }
    }
    for (frame = 1; frame <= (int)frames_f; ++frame) {
        pn_mpm_stats st;
        double t0 = pn_ex_seconds();
        if (w->time_s > 0.6) { /* the plate stops */
            pn_real here[2];
            here[0] = (pn_real)(0.08 + 0.3 * 0.6), here[1] = plate.center_m[1];
            pn_mpm_move_collider(w, plate_index, here, NULL);
        }
        if (pn_mpm_advance(w, (pn_real)(1.0 / 30), NULL, &st) != PN_OK) {
            fprintf(stderr, "materials: frame %d: %s\n", frame, pn_mpm_error(w));
            break;
        }
        if (!quiet)
            fprintf(stderr, "\rframe %d/%d  %d steps  %.0f ms   ", frame, (int)frames_f, st.substeps,
                    1e3 * (pn_ex_seconds() - t0));
        if (rgb) { /* colour by material: the speed legend's map at 4 levels */
            pn_render_desc d;
            pn_render_shape shapes[2];
            for (p = 0; p < w->n; ++p) color[p] = (pn_real)w->group[p] / (KINDS - 1);
            memset(&d, 0, sizeof d);
            memset(shapes, 0, sizeof shapes);
            d.width = view.width, d.height = view.height, d.dim = 2;
            d.hi[0] = view.hi[0], d.hi[1] = view.hi[1];
            d.radius_m = 0.3 * dx;
            d.has_floor = 1, d.floor_m = fl;
            d.field_hi = 1;
            d.time_s = (double)w->time_s;
            d.scale_bar = 1;
            d.title = view.title;
            for (i = 0; i < 2; ++i) {
                const pn_collider *c = &w->colliders[i];
                shapes[i].kind = c->shape == PN_SHAPE_BOX ? PN_RENDER_BOX : PN_RENDER_SPHERE;
                shapes[i].center[0] = (double)(c->center_m[0] + w->time_s * c->velocity_m_s[0]);
                shapes[i].center[1] = (double)(c->center_m[1] + w->time_s * c->velocity_m_s[1]);
                shapes[i].half_extent[0] = (double)c->half_extent_m[0], shapes[i].half_extent[1] = (double)c->half_extent_m[1];
                shapes[i].radius = (double)c->radius_m;
            }
            d.shapes = shapes, d.n_shapes = 2;
            if (pn_render_particles(&d, w->n, w->x, color, w->active, rgb)) {
                char path[1024];
                snprintf(path, sizeof path, "%s/frame_%04d.png", out, frame);
                if (png && !pn_png_write(path, view.width, view.height, rgb)) fprintf(stderr, "\nmaterials: cannot write %s\n", path);
                if (anim && frame % 2 == 0) pn_apng_add(anim, rgb); /* 15 fps: half the size */
            }
        }
    }
    if (!quiet) fprintf(stderr, "\n");
    if (anim) pn_apng_close(anim);
    for (k = 0; k < KINDS; ++k) { /* where each material ended up */
        double c[2] = {0, 0}, m = 0;
        for (p = 0; p < w->n; ++p)
            if (w->group[p] == f[k].group && w->active[p]) {
                c[0] += (double)(w->mass[p] * w->x[2 * p]), c[1] += (double)(w->mass[p] * w->x[2 * p + 1]);
                m += (double)w->mass[p];
            }
        printf("%-6s centre (%.3f, %.3f) m\n", names[k], m > 0 ? c[0] / m : 0, m > 0 ? c[1] / m : 0);
    }
    free(rgb);
    free(color);
    pn_mpm_destroy(w);
    return frame > (int)frames_f ? 0 : 1;
}
