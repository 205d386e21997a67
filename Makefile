# plastinet: `make run` (the demo) and `make test` (every test). Nothing else is needed to use
# the headers: copy plastinet.h into your project.
CC ?= cc
CXX ?= c++
CFLAGS ?= -std=c99 -O2 -Wall -Wextra -pedantic
CXXFLAGS ?= -std=c++17 -O2 -Wall -Wextra -pedantic
LDLIBS = -lm

.PHONY: all run run-material-point run-game-loop pictures test test-all test-sanitize bench-core bench-mpm bench-scale bench-fem bench-coupling bench-explicit bench-deposit bench-energies bench-coarse bench-rom rom-data clean examples models model-report crosscheck web test-web
# torch comes from Debian (apt-get install -y python3-torch); only gen/ and the cross-check use it
PY ?= /usr/bin/python3

all: examples

examples: build/material_point build/sand_column build/snowball build/materials build/game_loop build/metal_frame build/drop_on_sand build/rom_poke build/rom_tower

build/material_point: examples/material_point.c plastinet.h
	@mkdir -p build
	$(CC) $(CFLAGS) examples/material_point.c $(LDLIBS) -o $@

# The main demo: a 2D sand column collapsing under gravity (E = 1e7 Pa), implicit at dt = 1e-3 s
# in the stress formulation (Drucker-Prager as the stress's return mapping), then the explicit
# reference on the same particles; the JSON line compares their deposits (runout_ratio,
# height_ratio). PNG frames and an animated preview in build/sand_column_frames/.
# PlasticityNet: build/sand_column --energy pnet (sand_column --help says why it is not the default).
run: build/sand_column
	build/sand_column --png --apng --frames 30 --out build/sand_column_frames
	@echo "# frames: build/sand_column_frames/frame_0001.png ... frame_0030.png, animated: preview.png"

# What the MPM examples and bench/bench_mpm.c share (examples/common/): PNG/PLY output, the scenes, the mass IoU.
EXAMPLE_DEPS = examples/common/pn_example.h examples/common/pn_render.h examples/common/pn_png.h plastinet.h plastinet_mpm.h models/pn_model_sand_2d.h \
    models/pn_model_sand_3d.h models/pn_model_snow_2d.h models/pn_model_snow_3d.h

build/sand_column: examples/sand_column.c $(EXAMPLE_DEPS) models/pn_models.h
	@mkdir -p build
	$(CC) $(CFLAGS) examples/sand_column.c $(LDLIBS) -o $@

# FEM: a steel frame crushed by a plate (build/metal_frame --help; --png --vtu --obj).
build/metal_frame: examples/metal_frame.c examples/common/pn_frame.h $(EXAMPLE_DEPS) models/pn_model_metal_2d.h models/pn_model_metal_3d.h \
    models/pn_model_metal_nh_2d.h models/pn_model_metal_nh_3d.h models/pn_model_metal_nh_return_2d.h \
    models/pn_model_metal_nh_return_3d.h models/pn_model_metal_nh_any_2d.h models/pn_model_metal_nh_any_3d.h
	@mkdir -p build
	$(CC) $(CFLAGS) examples/metal_frame.c $(LDLIBS) -o $@

# MPM-FEM coupling: a stiff block (E 1e9 Pa) dropped onto a sand bed, one implicit solve for
# both (build/drop_on_sand --help; --png --apng, --ply --vtu --obj).
build/drop_on_sand: examples/drop_on_sand.c examples/common/pn_drop.h $(EXAMPLE_DEPS)
	@mkdir -p build
	$(CC) $(CFLAGS) examples/drop_on_sand.c $(LDLIBS) -o $@

# A snowball thrown at a frictional floor (build/snowball --help; --png --out DIR for frames).
build/snowball: examples/snowball.c $(EXAMPLE_DEPS)
	@mkdir -p build
	$(CC) $(CFLAGS) examples/snowball.c $(LDLIBS) -o $@

# Sand, rubber, steel and snow with a post and a moving plate (build/materials --help).
build/materials: examples/materials.c $(EXAMPLE_DEPS)
	@mkdir -p build
	$(CC) $(CFLAGS) examples/materials.c $(LDLIBS) -o $@

# C++17: a 3D sandbox stepped once per 60 Hz frame with pn_mpm_advance; prints ms per frame.
build/game_loop: examples/game_loop.cpp examples/common/pn_render.h examples/common/pn_png.h plastinet.h plastinet_mpm.h
	@mkdir -p build
	$(CXX) $(CXXFLAGS) examples/game_loop.cpp -o $@

run-game-loop: build/game_loop
	build/game_loop --frames 60

# The material-point driver on a von Mises tensile test (uniaxial stress, linear hardening):
# prints the stress-strain curve.
run-material-point: build/material_point
	@echo "# von Mises steel, uniaxial stress, linear hardening (build/material_point --help for more)"
	@build/material_point --dim 3 --plastic von_mises --path uniaxial_stress --steps 40 \
	    --max-strain 0.01 --out build/run.csv
	@awk -F, '/^#/ {next} /^step,/ {for (i = 1; i <= NF; i++) c[$$i] = i; \
	    printf "%10s %14s %17s %12s\n", "step", "axial_strain", "axial_stress_MPa", "plastic_h"; next} \
	    {printf "%10d %14.6f %17.3f %12.6f\n", $$c["step"], $$c["axial_log_strain"], \
	    $$c["axial_sigma"] / 1e6, $$c["h"]}' build/run.csv
	@echo "# full CSV (F, Fe, Kirchhoff and Cauchy stress, h, yield value per step): build/run.csv"

test:
	@tests/run.sh

# make test with the whole compile matrix (4 compilers x 6 configurations x 2 levels, and the
# host's vector units) and every case of the tests' sweeps (PN_TEST_FULL=1): what CI runs.
# tests/run.sh's top says what runs in make test, make test-all and make test-sanitize.
test-all:
	@FULL=1 tests/run.sh

# Nanoseconds per call of the core (SVD, energies, return mappings), 2D and 3D.
bench-core: bench/bench_core.c bench/bench_util.h plastinet.h
	@mkdir -p build
	$(CC) $(CFLAGS) bench/bench_core.c $(LDLIBS) -o build/bench_core
	build/bench_core --csv build/bench_core.csv

# MPM speed against accuracy (bench/README.md): sand column and snowball, 2D and 3D, explicit
# reference, fair explicit baseline, implicit PlasticityNet and lagged at dt 1e-4..1e-2; a
# Young's-modulus sweep. build/bench_mpm.{csv,svg,md}, build/bench_mpm_esweep.{csv,svg}.
# BENCH_MPM_FLAGS=--quick for a smoke test in seconds.
bench-mpm: build/bench_mpm
	build/bench_mpm --out build $(BENCH_MPM_FLAGS)
	@cat build/bench_mpm.md

# The implicit sand column at user sizes (bench_mpm --scale; bench/bench_mpm.c's top): 3D at
# 25k, 100k, 400k particles and 2D at 20k, 100k, E 1e7 and 1e9 Pa, 1.5 s each: fair explicit,
# reference, the stress formulation at the advection limit and 1/60 s. Hours at 400k: each run
# goes to build/bench_scale.csv as it ends and a rerun skips those. build/bench_scale.{csv,md}.
# BENCH_SCALE_FLAGS="--scale-dim 2 --scale-res2 16 --duration 0.1 --sweep-E 1e7": a smoke test.
bench-scale: build/bench_mpm
	build/bench_mpm --scale --out build $(BENCH_SCALE_FLAGS)
	@cat build/bench_scale.md

# FEM: the metal frame, accuracy at a softened stiffness and speed at 200 GPa (bench/bench_fem.c;
# 2D then 3D; BENCH_FEM_FLAGS=--quick for a smoke test).
# Then the linear solvers against the mesh size (bench/bench_fem_linear.c; about an hour).
bench-fem: build/bench_fem build/bench_fem_linear
	build/bench_fem --dim 2 --out build $(BENCH_FEM_FLAGS)
	build/bench_fem --dim 3 --out build $(BENCH_FEM_FLAGS)
	build/bench_fem_linear --out build $(BENCH_FEM_LINEAR_FLAGS)
	@cat build/bench_fem_2d.md build/bench_fem_3d.md build/bench_fem_linear.md

# MPM-FEM coupling: the block dropped on sand, the explicit reference and the fair explicit
# baseline against implicit at 1e-3 and 1e-2 s (bench/bench_coupling.c; 2D then 3D, about 1.5
# hours; --dts and --thetas choose the implicit runs; BENCH_COUPLING_FLAGS=--quick for a smoke test; the references are kept in build/ref_cache).
bench-coupling: build/bench_coupling
	build/bench_coupling --dim 2 --out build --ref-cache build/ref_cache $(BENCH_COUPLING_FLAGS)
	build/bench_coupling --dim 3 --res 24 --T 0.05 --out build --ref-cache build/ref_cache $(BENCH_COUPLING_FLAGS)
	@cat build/bench_coupling_2d.md build/bench_coupling_3d.md

build/bench_coupling: bench/bench_coupling.c examples/common/pn_drop.h $(EXAMPLE_DEPS)
	@mkdir -p build
	$(CC) $(CFLAGS) bench/bench_coupling.c $(LDLIBS) -o $@

build/bench_fem: bench/bench_fem.c examples/common/pn_frame.h $(EXAMPLE_DEPS)
	@mkdir -p build
	$(CC) $(CFLAGS) bench/bench_fem.c $(LDLIBS) -o $@

build/bench_fem_linear: bench/bench_fem_linear.c examples/common/pn_frame.h $(EXAMPLE_DEPS)
	@mkdir -p build
	$(CC) $(CFLAGS) bench/bench_fem_linear.c $(LDLIBS) -o $@

build/bench_mpm: bench/bench_mpm.c $(EXAMPLE_DEPS)
	@mkdir -p build
	$(CC) $(CFLAGS) bench/bench_mpm.c $(LDLIBS) -o $@

# Explicit MPM throughput (bench/bench_explicit.c): the 88-line MLS-MPM scene (30k particles,
# n 80 and 256) in float and double, then the 2D/3D sweep 1e3 .. 1e6 particles at 1 and 2
# threads (build/bench_explicit_sweep.{csv,md}). With MLS88_DIR=/path/to/a/copy of that
# program, it runs beside ours first (bench/mls88_side_by_side.sh, build/mls88_side_by_side.md).
# BENCH_EXPLICIT_MAX=100000 for a quicker sweep.
BENCH_EXPLICIT_MAX ?= 1000000
bench-explicit: build/bench_explicit build/bench_explicit_float
	@if [ -n "$(MLS88_DIR)" ]; then MLS88_DIR="$(MLS88_DIR)" sh bench/mls88_side_by_side.sh 0.1; fi
	build/bench_explicit_float --n 80 --steps 1000 --threads 1
	build/bench_explicit_float --n 256 --steps 1000 --threads 1
	build/bench_explicit --n 80 --steps 1000 --threads 1
	build/bench_explicit --n 256 --steps 1000 --threads 1
	build/bench_explicit --sweep --max $(BENCH_EXPLICIT_MAX) --csv build/bench_explicit_sweep.csv --md build/bench_explicit_sweep.md
	@cat build/bench_explicit_sweep.md

build/bench_explicit: bench/bench_explicit.c plastinet.h plastinet_mpm.h
	@mkdir -p build
	$(CC) $(CFLAGS) -fopenmp bench/bench_explicit.c $(LDLIBS) -o $@

build/bench_explicit_float: bench/bench_explicit.c plastinet.h plastinet_mpm.h
	@mkdir -p build
	$(CC) $(CFLAGS) -fopenmp -DPN_REAL=float bench/bench_explicit.c $(LDLIBS) -o $@

# The implicit energies in the sand column at aspect ratios 0.5-8 (bench/energies_in_scenes.sh):
# PlasticityNet (1 and 2 passes), frozen-yield DP, lagged and the stress formulation at dt 1e-3 s
# and 1/60 s against the explicit reference. bench/results/energies_in_scenes_2d.md;
# BENCH_ENERGIES_FLAGS="--dim 3" for 3D (aspects 0.5-2 at res 24, 4 and 8 narrower at res 48).
bench-energies: build/sand_column
	sh bench/energies_in_scenes.sh $(BENCH_ENERGIES_FLAGS)

# Is the explicit reference converged? (bench/bench_deposit.c): the 2D sand column's deposit at
# res 64/128/256 and at step halvings, the settled pile, the snow press at step halvings.
# build/bench_deposit.md. BENCH_DEPOSIT_FLAGS=--quick for a smoke test.
bench-deposit: build/bench_deposit
	build/bench_deposit --md build/bench_deposit.md $(BENCH_DEPOSIT_FLAGS)
	@cat build/bench_deposit.md

build/bench_deposit: bench/bench_deposit.c $(EXAMPLE_DEPS)
	@mkdir -p build
	$(CC) $(CFLAGS) bench/bench_deposit.c $(LDLIBS) -o $@

# The stress formulation's coarse correction against the sweeps alone as the grid grows
# (bench/bench_coarse.c): an elastic 3D block at res 32, 48, 64, one step per 1/60 s frame,
# against the sweeps at a 100x tighter tolerance. build/bench_coarse.md (about 15 minutes).
bench-coarse: build/bench_coarse
	build/bench_coarse --reference --md build/bench_coarse.md $(BENCH_COARSE_FLAGS)
	@cat build/bench_coarse.md

build/bench_coarse: bench/bench_coarse.c bench/bench_util.h plastinet.h plastinet_mpm.h
	@mkdir -p build
	$(CC) $(CFLAGS) bench/bench_coarse.c $(LDLIBS) -o $@

# ---- reduced-order MPM (plastinet_rom.h; docs/rom.md) ------------------------------------------
# A jelly cylinder poked ten times from random directions, on the shipped reduced model
# (build/rom_poke --help; --png for frames).
build/rom_poke: examples/rom_poke.c examples/common/pn_rom_scenes.h plastinet_rom.h models/rom_poke.h $(EXAMPLE_DEPS)
	@mkdir -p build
	$(CC) $(CFLAGS) examples/rom_poke.c $(LDLIBS) -o $@

# The reduced tower, one implicit step per frame, drawn at any resolution
# (build/rom_tower --refine 3 --png: 1.56 million points; --help).
build/rom_tower: examples/rom_tower.c examples/common/pn_rom_scenes.h plastinet_rom.h models/rom_tower.h $(EXAMPLE_DEPS)
	@mkdir -p build
	$(CC) $(CFLAGS) examples/rom_tower.c $(LDLIBS) -o $@

# Full-order snapshots of the scenes the ROM models are trained on (gen/rom_data.c, into
# data/rom/; resumable: run it again after a cut and it continues). About 3 hours on 2 cores,
# most of it the tower; gen/README.md shows how to spread the instances over machines.
ROM_SCENES ?= cylinder cuboid poke poke_seq tower
build/rom_data: gen/rom_data.c examples/common/pn_rom_scenes.h plastinet.h plastinet_mpm.h
	@mkdir -p build
	$(CC) $(CFLAGS) -fopenmp gen/rom_data.c $(LDLIBS) -o $@

rom-data: build/rom_data
	for s in $(ROM_SCENES); do build/rom_data $$s --out data/rom || exit 1; done
	build/rom_data cuboid --fine 2 --split test --out data/rom

# The reduced models against full-order MPM on the test instances (bench/bench_rom.c):
# build/bench_rom.{md,csv,svg}. Needs make rom-data. BENCH_ROM_FLAGS=--instances 1 for a quick look.
bench-rom: build/bench_rom
	build/bench_rom --out build $(BENCH_ROM_FLAGS)
	@cat build/bench_rom.md

build/bench_rom: bench/bench_rom.c examples/common/pn_rom_scenes.h plastinet_rom.h $(EXAMPLE_DEPS) $(wildcard models/rom_*.h) models/pn_rom_models.h
	@mkdir -p build
	$(CC) $(CFLAGS) -fopenmp bench/bench_rom.c $(LDLIBS) -o $@

# Train (resuming checkpoints), export and measure the shipped models: all, or MODEL=name.
models:
	$(PY) gen/make_models.py $(MODEL)

# models/REPORT.md: quality and cost of every model in models/ (bench/model_report.c).
model-report: build/model_report
	build/model_report --out models/REPORT.md
	@cat models/REPORT.md

build/model_report: bench/model_report.c bench/bench_util.h plastinet.h $(wildcard models/*.h)
	@mkdir -p build
	$(CC) $(CFLAGS) bench/model_report.c $(LDLIBS) -o $@

# C against torch (targets, every model); also part of `make test` when torch is installed.
crosscheck:
	$(PY) gen/crosscheck.py

# The test binaries under AddressSanitizer and UBSan, the sweeps' subsets (CI; the compile
# matrix, the torch cross-checks and the examples run in make test-all).
test-sanitize:
	@SANITIZE=1 tests/run.sh

# The fuzz targets (tests/fuzz/README.md): FUZZ_SECONDS per target under clang's libFuzzer
# (without it: the corpus replayed once per target).
FUZZ_SECONDS ?= 20
.PHONY: fuzz
fuzz:
	@tests/fuzz/run.sh $(FUZZ_SECONDS)

clean:
	rm -rf build

# ---- the browser demo (examples/web): 2D sand and snow in WebAssembly -----------------------
# `make web` builds build/web/ (index.html, app.js, demo.js, demo.wasm; serve it over http, e.g.
# python3 -m http.server -d build/web). Debian's emscripten: apt-get install -y emscripten; its
# system libraries come prebuilt in a frozen cache, so no EM_CACHE is needed. NODE_PATH lets emcc
# find Debian's node modules (acorn) when node itself is not Debian's (e.g. NodeSource).
# `make test-web` drives the page in headless Chromium (apt-get install -y chromium chromium-driver).
EMCC ?= emcc
WEB_CFLAGS = -std=c99 -O2 -Wall -Wextra -pedantic
WEB_LDFLAGS = -sALLOW_MEMORY_GROWTH=1 -sMODULARIZE=1 -sEXPORT_NAME=createPlastinetDemo \
    -sENVIRONMENT=web -sFILESYSTEM=0 -sEXPORTED_RUNTIME_METHODS=HEAPF32
WEB_FILES = build/web/demo.js build/web/index.html build/web/app.js

web: $(WEB_FILES)

build/web/demo.js: examples/web/demo.c plastinet.h plastinet_mpm.h
	@command -v $(EMCC) >/dev/null 2>&1 || { echo "make web: $(EMCC) not found; install emscripten (Debian: apt-get install -y emscripten)" >&2; exit 1; }
	@mkdir -p build/web
	NODE_PATH=$${NODE_PATH:+$$NODE_PATH:}/usr/share/nodejs $(EMCC) $(WEB_CFLAGS) $(WEB_LDFLAGS) examples/web/demo.c -o $@

build/web/index.html: examples/web/index.html
	@mkdir -p build/web
	cp examples/web/index.html $@

build/web/app.js: examples/web/app.js
	@mkdir -p build/web
	cp examples/web/app.js $@

test-web: web
	$(PY) tests/web_test.py

# ---- the README's pictures (docs/images): animated previews the examples write -----------------
pictures: build/sand_column build/snowball build/materials build/drop_on_sand
	build/sand_column --apng --out build/pictures/sand_2d --quiet
	build/sand_column --dim 3 --res 32 --jitter --integrator explicit --dt 1e-4 --no-reference --apng --frames 15 --fps 15 --out build/pictures/sand_3d --quiet
	build/snowball --res 128 --jitter --apng --frames 15 --fps 15 --out build/pictures/snow_2d --quiet
	@mkdir -p docs/images
	cp build/pictures/sand_2d/preview.png docs/images/sand_column_2d.png
	cp build/pictures/sand_3d/preview.png docs/images/sand_column_3d.png
	build/materials --apng --out build/pictures/materials --quiet
	cp build/pictures/snow_2d/preview.png docs/images/snowball_2d.png
	cp build/pictures/materials/preview.png docs/images/materials_2d.png
	build/drop_on_sand --res 128 --png --frames 4 --out build/pictures/drop >/dev/null
	cp build/pictures/drop/frame_0004.png docs/images/drop_on_sand_2d.png
	@if [ -f build/web_test/after.png ]; then cp build/web_test/after.png docs/images/web_demo.png; \
	else echo "docs/images/web_demo.png: run make test-web first for the browser screenshot"; fi
