# Two commands do everything on a fresh Debian/Ubuntu machine (see README):
#   make run    render the default scenario on the embedded procedural terrain
#   make test   the whole test suite, with Vulkan validation (incl. synchronization) on
# Both install the system packages they need when they are missing (apt-get, as root or via
# sudo); otherwise they print the exact command to run.

# libgdal-dev: GDAL 3.6 (reading DEMs; the gdal crate links it, found through pkg-config),
# libproj-dev + proj-data: PROJ 9.1 and its EPSG database (coordinate transformations).
# glslang-tools: glslangValidator, the build-time compiler of the GLSL shader stages naga lacks
# (tessellation, task/mesh; build.rs runs it).
RUN_PACKAGES  := libvulkan1 mesa-vulkan-drivers glslang-tools libgdal-dev libproj-dev proj-data pkg-config
TEST_PACKAGES := $(RUN_PACKAGES) vulkan-validationlayers gcc python3
CARGO ?= cargo
# The shared real data (never committed): ../shared/data by default.
SHARED ?= ../shared
export VKTERRAIN_SHARED_DATA ?= $(abspath $(SHARED)/data)
# Tests and CI's benchmarks run on lavapipe from Mesa >= 24: on Debian 12 (Mesa 22.3) the
# pinned bookworm-backports Mesa 25.0.7, unpacked into target/lavapipe-25, nothing installed
# (scripts/lavapipe.sh; docs/architecture.md "Which lavapipe"). VKTERRAIN_LAVAPIPE=system opts out.
LAVAPIPE = lvp_env=$$(scripts/lavapipe.sh) && env $$lvp_env

.PHONY: run test doc bench bench-udlod bench-eval bench-eval-short bench-clipmap bench-ring bench-ring-fuzz bench-preprocess bench-startup fuzz data data-srtm data-pyrenees data-franconia data-proc4k data-default deps deps-test

# The main job: UDLOD through the chunked clipmap over the embedded procedural terrain (its tile
# pyramid is generated once into target/data/default).
run: deps data-default
	$(CARGO) run --release --locked -- render --config config/default.toml

test: deps-test
	$(LAVAPIPE) VKTERRAIN_VALIDATION=1 $(CARGO) test --locked

# The API docs, failing on a broken or private intra-doc link (target/doc/vkterrain/).
doc: deps
	RUSTDOCFLAGS="-D warnings" $(CARGO) doc --no-deps --lib --locked

bench: deps
	$(LAVAPIPE) $(CARGO) bench --locked --bench frame_time

# UDLOD vs brute force on the procedural, Puget Sound and SRTM data (../shared/data).
bench-udlod: deps data-srtm
	$(CARGO) bench --locked --bench udlod

# The ring: copy vs zero-copy publishing, consumers, wake-up latency (docs/ring.md).
bench-ring: deps
	$(CARGO) bench --locked --bench ring

# 10^6 hostile segments against the Rust ring reader (CI runs 3000 in tests/ring.rs).
bench-ring-fuzz: deps
	$(CARGO) bench --locked --bench ring_fuzz

data: data-srtm data-pyrenees data-franconia

data-srtm: target/data/n48w125/manifest.json
data-pyrenees: out/datasets/pyrenees/manifest.json
data-franconia: out/datasets/franconia/manifest.json

# Data sets are rebuilt when the format (src/dataset/manifest.rs) changes.
out/datasets/pyrenees/manifest.json: src/dataset/manifest.rs
	$(CARGO) run --release --locked -- preprocess $(SHARED)/data/srtm/N41E001.hgt.zip $(SHARED)/data/srtm/N42E001.hgt.zip --out out/datasets/pyrenees --force

out/datasets/franconia/manifest.json: src/dataset/manifest.rs
	$(CARGO) run --release --locked -- preprocess $(SHARED)/data/srtm/N49E011.hgt.zip $(SHARED)/data/srtm/N50E011.hgt.zip --out out/datasets/franconia --force

# The speed/accuracy evaluation at CI size (short) or full size: see docs/eval.md.
bench-eval: deps data
	$(LAVAPIPE) $(CARGO) bench --locked --bench eval

bench-eval-short: deps
	$(LAVAPIPE) VKTERRAIN_EVAL_SHORT=1 $(CARGO) bench --locked --bench eval

# The clipmap's fast flight over a 4097² procedural pyramid much larger than the atlas.
bench-clipmap: deps data-proc4k
	$(CARGO) bench --locked --bench clipmap

data-proc4k: target/data/proc4k/manifest.json
data-default: target/data/default/manifest.json

target/data/default/manifest.json: src/dataset/manifest.rs
	$(CARGO) run --release --locked -- preprocess --procedural --style alpine --size 4097 --spacing 30 --max-height 3500 --feature-size 16000 --node-size 64 --out target/data/default --force

target/data/proc4k/manifest.json: src/dataset/manifest.rs
	$(CARGO) run --release --locked -- preprocess --procedural --size 4097 --node-size 64 --out target/data/proc4k --force

target/data/n48w125/manifest.json: src/dataset/manifest.rs
	$(CARGO) run --release --locked -- preprocess $(SHARED)/data/srtm/N48W125.hgt.zip --out target/data/n48w125 --force

# Preprocessing throughput and peak memory: every shared data set and procedural 4097²/16385²,
# one thread and all (docs/dataset-format.md; VKT_BENCH_* variables in benches/preprocess.rs).
bench-preprocess: deps
	$(CARGO) bench --locked --bench preprocess

# UDLOD start-up: stored tile statistics against computing them from level 0.
bench-startup: deps data-proc4k
	$(CARGO) bench --locked --bench startup

# 10^6 fuzz cases over the readers that remain ours (manifest, level files, statistics, tile
# PNG decoding); not part of `make test`.
fuzz: deps
	$(CARGO) bench --locked --bench fuzz_readers

deps:
	@scripts/ensure-packages.sh $(RUN_PACKAGES)

deps-test:
	@scripts/ensure-packages.sh $(TEST_PACKAGES)
	@scripts/ensure-python.sh
