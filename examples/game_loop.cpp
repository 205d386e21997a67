// game_loop.cpp: plastinet in a C++17 game loop. A 3D sandbox (a heap of sand on a floor), a
// sphere that ploughs through it like a player's tool, one pn_mpm_advance call per 60 Hz
// frame; prints the milliseconds each frame took and what a frame costs per particle.
// Build: c++ -std=c++17 -O2 examples/game_loop.cpp -o game_loop     (add -fopenmp for threads)
// Usage: game_loop [--frames N] [--res N] [--E PA] [--implicit] [--stress] [--stress-cells]
//                  [--stress-cells-first] [--png DIR]
//   --implicit   one implicit step per frame (frozen-yield Drucker-Prager energy) instead of
//                explicit steps at pn_mpm_stable_dt; the advection limit may still split it
//   --stress     the same with the stress formulation (PN_MPM_FORMULATION_STRESS)
//   --stress-cells, --stress-cells-first: the stress formulation with a stress per cell, or
//                per cell then per particle (pn_mpm_implicit_desc.stress_unknowns)
//   --png DIR    a picture of every 10th frame into DIR (created; examples/common/pn_render.h)
#define PLASTINET_IMPLEMENTATION
#define PN_NO_FEM /* a game that simulates particles only: FEM and coupling left out */
#include "../plastinet.h"
#include "../plastinet_mpm.h"
#include "common/pn_render.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <system_error>
#include <vector>

namespace {

struct Options {
    int frames = 60, res = 32; // one second of play; 120 frames took about a minute on one core
    double E = 1e6; // Pa: softer than real sand (1e7 - 1e8) so that explicit steps are few
    bool implicit = false, stress = false;
    pn_mpm_stress_unknowns where = PN_MPM_STRESS_PARTICLES;
    std::string png;
};

bool parse(int argc, char **argv, Options &o) {
    for (int k = 1; k < argc; ++k) {
        std::string a = argv[k];
        const char *v = k + 1 < argc ? argv[k + 1] : nullptr;
        auto number = [&](double &out) {
            char *end = nullptr;
            if (!v || (out = std::strtod(v, &end), end == v || *end)) {
                std::fprintf(stderr, "game_loop: %s needs a number\n", a.c_str());
                return false;
            }
            ++k;
            return true;
        };
        double x = 0;
        if (a == "--help" || a == "-h") {
            std::printf("usage: game_loop [flags]   a 3D sandbox and a plough, one pn_mpm_advance per 60 Hz frame\n"
                        "  --frames N             frames [60: one second; 120 before issue 42]\n"
                        "  --res N                grid cells per axis, 16 .. 256 [32]\n"
                        "  --E PA                 the sand's Young's modulus [1e6]\n"
                        "  --implicit             one implicit step per frame (frozen-yield Drucker-Prager energy)\n"
                        "                         [explicit steps at pn_mpm_stable_dt]\n"
                        "  --stress               the same in the stress formulation (PN_MPM_FORMULATION_STRESS)\n"
                        "  --stress-cells  --stress-cells-first   the stress formulation with a stress per cell,\n"
                        "                         or per cell then per particle (pn_mpm_implicit_desc.stress_unknowns)\n"
                        "  --png DIR              a picture of every 10th frame into DIR (created)\n"
                        "  --help                 this text\n");
            std::exit(0);
        } else if (a == "--implicit") {
            o.implicit = true;
        } else if (a == "--stress") {
            o.implicit = o.stress = true;
        } else if (a == "--stress-cells") {
            o.implicit = o.stress = true, o.where = PN_MPM_STRESS_CELLS;
        } else if (a == "--stress-cells-first") {
            o.implicit = o.stress = true, o.where = PN_MPM_STRESS_CELLS_THEN_PARTICLES;
        } else if (a == "--frames" && number(x) && x >= 1) {
            o.frames = static_cast<int>(x);
        } else if (a == "--res" && number(x) && x >= 16 && x <= 256) {
            o.res = static_cast<int>(x);
        } else if (a == "--E" && number(x) && x > 0) {
            o.E = x;
        } else if (a == "--png" && v) {
            o.png = v;
            ++k;
        } else {
            std::fprintf(stderr, "game_loop: bad flag or value '%s' (--help lists them)\n", a.c_str());
            return false;
        }
    }
    return true;
}

} // namespace

int main(int argc, char **argv) {
    Options opt;
    if (!parse(argc, argv, opt)) return 2;
    const double L = 1.0, dx = L / opt.res, fps = 60;

    // The world: a 1 m box, walls 3 cells thick, a floor with Coulomb friction.
    pn_mpm_desc wd{};
    wd.dim = 3;
    wd.res[0] = wd.res[1] = wd.res[2] = opt.res;
    wd.dx_m = dx;
    wd.gravity[1] = -9.81;
    wd.boundary = PN_BOUNDARY_SEPARATE;
    wd.friction = 0.5;
    wd.filter_time_s = 2e-3;

    // The sand: a heap, a lattice of 2 x 2 x 2 particles per cell, jittered.
    pn_mpm_fill_desc heap{};
    heap.shape = PN_MPM_FILL_BOX;
    heap.center_m[0] = 0.5, heap.center_m[1] = 3 * dx + 0.15, heap.center_m[2] = 0.5;
    heap.half_extent_m[0] = 0.25, heap.half_extent_m[1] = 0.15, heap.half_extent_m[2] = 0.25;
    heap.jitter = 1;
    char why[256] = "";
    size_t n = 0;
    if (pn_mpm_fill_count(&wd, &heap, &n, why, sizeof why) != PN_OK) return std::fprintf(stderr, "game_loop: %s\n", why), 1;
    wd.max_particles = n;
    pn_mpm_world *w = nullptr;
    if (pn_mpm_create(&wd, &w, why, sizeof why) != PN_OK) return std::fprintf(stderr, "game_loop: %s\n", why), 1;

    pn_material_desc md{};
    md.plastic = PN_PLASTIC_DRUCKER_PRAGER;
    md.youngs_modulus_pa = opt.E;
    md.poisson_ratio = 0.3;
    md.friction_angle_deg = 35;
    pn_material sand;
    if (pn_material_init(&sand, &md, why, sizeof why) != PN_OK) return std::fprintf(stderr, "game_loop: %s\n", why), 1;
    heap.group = pn_mpm_add_group(w, &sand, 1600);
    pn_collider tool{};
    tool.shape = PN_SHAPE_SPHERE;
    tool.boundary = PN_BOUNDARY_SLIP;
    tool.radius_m = 0.08;
    tool.center_m[0] = 0.1, tool.center_m[1] = 0.2, tool.center_m[2] = 0.5;
    int tool_index = -1;
    if (heap.group < 0 || pn_mpm_fill(w, &heap, nullptr) != PN_OK ||
        pn_mpm_group_set_energy(w, heap.group, PN_ENERGY_DP, nullptr) != PN_OK ||
        pn_mpm_add_collider(w, &tool, &tool_index) != PN_OK)
        return std::fprintf(stderr, "game_loop: %s\n", pn_mpm_error(w)), 1;

    pn_mpm_advance_desc step{};
    pn_mpm_implicit_desc solve{};
    solve.formulation = opt.stress ? PN_MPM_FORMULATION_STRESS : PN_MPM_FORMULATION_ENERGY;
    solve.stress_unknowns = opt.where;
    step.integrator = opt.implicit ? PN_MPM_IMPLICIT : PN_MPM_EXPLICIT;
    step.max_step_s = opt.implicit ? 1 / fps : 0;
    step.implicit = &solve;

    std::vector<unsigned char> rgb;
    pn_render_desc view{};
    if (!opt.png.empty()) {
        std::error_code err;
        std::filesystem::create_directories(opt.png, err);
        if (err) {
            std::fprintf(stderr, "game_loop: cannot create the folder %s: %s\n", opt.png.c_str(), err.message().c_str());
            pn_mpm_destroy(w);
            return 1;
        }
        rgb.resize(960 * 540 * 3);
        view.width = 960, view.height = 540, view.dim = 3;
        view.hi[0] = view.hi[1] = view.hi[2] = L;
        view.radius_m = 0.3 * dx;
        view.has_floor = 1, view.floor_m = 3 * dx;
        view.yaw_deg = 30, view.pitch_deg = 25, view.scale_bar = 1;
        view.title = "game_loop: sand and a plough";
        view.n_shapes = 1;
    }

    std::printf("game_loop: %zu particles, %s, E %.3g Pa, grid %d^3\n", n,
                opt.stress     ? "one implicit step per frame, stress formulation"
                : opt.implicit ? "one implicit step per frame"
                               : "explicit steps at pn_mpm_stable_dt",
                opt.E, opt.res);
    double total_ms = 0, worst_ms = 0;
    long steps = 0;
    for (int frame = 1; frame <= opt.frames; ++frame) {
        // the tool sweeps across the box and back, through the heap
        double t = frame / fps, s = std::sin(t * 1.5);
        pn_real center[3] = {static_cast<pn_real>(0.5 + 0.4 * s), static_cast<pn_real>(3 * dx + 0.12), 0.5};
        pn_real velocity[3] = {static_cast<pn_real>(0.6 * std::cos(t * 1.5)), 0, 0};
        pn_mpm_move_collider(w, tool_index, center, velocity);

        auto t0 = std::chrono::steady_clock::now();
        pn_mpm_stats st;
        pn_result r = pn_mpm_advance(w, static_cast<pn_real>(1 / fps), &step, &st);
        double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
        if (r != PN_OK) {
            std::fprintf(stderr, "game_loop: frame %d: %s\n", frame, pn_mpm_error(w));
            pn_mpm_destroy(w);
            return 1;
        }
        total_ms += ms;
        worst_ms = std::fmax(worst_ms, ms);
        steps += st.substeps;
        if (frame % 10 == 0) std::printf("frame %4d  %7.2f ms  %3d steps\n", frame, ms, st.substeps);
        if (!opt.png.empty() && frame % 10 == 0) {
            pn_render_shape shape{};
            shape.kind = PN_RENDER_SPHERE;
            for (int i = 0; i < 3; ++i) shape.center[i] = center[i];
            shape.radius = tool.radius_m;
            view.shapes = &shape;
            view.time_s = t;
            char path[1024];
            std::snprintf(path, sizeof path, "%s/frame_%04d.png", opt.png.c_str(), frame);
            if (!pn_render_particles(&view, w->n, w->x, nullptr, w->active, rgb.data()) ||
                !pn_png_write(path, 960, 540, rgb.data()))
                std::fprintf(stderr, "game_loop: cannot write %s\n", path);
        }
    }
    std::printf("game_loop: %.2f ms per frame on average, %.2f ms at worst, %.1f steps per frame, "
                "%.1f ns per particle-step\n",
                total_ms / opt.frames, worst_ms, static_cast<double>(steps) / opt.frames,
                1e6 * total_ms / static_cast<double>(steps) / static_cast<double>(n));
    pn_mpm_destroy(w);
    return 0;
}
