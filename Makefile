# ltmapper: the two set-up commands (make demo, make test) and friends.
BUILD_DIR ?= build
JOBS ?= $(shell nproc)
CMAKE_FLAGS ?=
CTEST_FLAGS ?=

.PHONY: all deps configure build test bench demo clean fuzz fuzz-build test-sanitize

all: build

deps:
	bash scripts/install-deps.sh

configure: deps
	cmake -S . -B $(BUILD_DIR) -DCMAKE_BUILD_TYPE=Release $(CMAKE_FLAGS)

build: configure
	cmake --build $(BUILD_DIR) -j $(JOBS)

# Installs dependencies, builds everything (Release) and runs every test.
test: build
	cd $(BUILD_DIR) && ctest --output-on-failure -j $(JOBS) $(CTEST_FLAGS)

# Micro benchmarks and the end-to-end benchmark script (slow; not part of CI).
bench: build
	bash bench/run_all.sh $(BUILD_DIR)

# Installs, builds, simulates the default scenario, runs the whole pipeline, evaluates it and
# writes out/demo/report.html.
demo: build
	bash scripts/demo.sh out/demo $(BUILD_DIR)

# libFuzzer harnesses (fuzz/) for every reader, built with clang + ASan + UBSan in build-fuzz/
# (only the io, map, removert, geometry and core libraries and the harnesses), then each run for
# FUZZ_SECONDS (the acceptance run of issue 21 is FUZZ_SECONDS=300), FUZZ_PARALLEL harnesses at a
# time (one core each); prints harness / runs / crashes.
# FUZZ_HARNESSES picks some (e.g. FUZZ_HARNESSES="pcd ply"). Not part of build / test.
FUZZ_DIR ?= build-fuzz
FUZZ_SECONDS ?= 60
FUZZ_HARNESSES ?= pcd ply g2o poses kitti_bin scd config blob
FUZZ_JOBS ?= 2
FUZZ_PARALLEL ?= 1

fuzz-build:
	CC=clang CXX=clang++ cmake -S . -B $(FUZZ_DIR) -DCMAKE_BUILD_TYPE=RelWithDebInfo -DLTM_FUZZ=ON \
	  -DLTM_BUILD_TESTS=OFF -DLTM_BUILD_BENCH=OFF -DLTM_PYTHON=OFF
	cmake --build $(FUZZ_DIR) --target fuzz_all -j $(FUZZ_JOBS)

fuzz: fuzz-build
	FUZZ_SECONDS=$(FUZZ_SECONDS) FUZZ_PARALLEL=$(FUZZ_PARALLEL) bash fuzz/run.sh $(FUZZ_DIR) $(FUZZ_HARNESSES)

# The whole suite under ASan + UBSan (GCC) in build-asan/; the CLI tests run the sanitized
# ltmapper of that build. No Python bindings (an ASan module needs the runtime preloaded) and no
# benchmarks. A full build of its own: slow (run time not yet measured; see README.md).
ASAN_DIR ?= build-asan
test-sanitize: deps
	cmake -S . -B $(ASAN_DIR) -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	  -DCMAKE_CXX_FLAGS="-fsanitize=address,undefined -fno-omit-frame-pointer" \
	  -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=address,undefined" \
	  -DCMAKE_SHARED_LINKER_FLAGS="-fsanitize=address,undefined" \
	  -DLTM_BUILD_BENCH=OFF -DLTM_PYTHON=OFF $(CMAKE_FLAGS)
	cmake --build $(ASAN_DIR) -j $(JOBS)
	cd $(ASAN_DIR) && UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
	  ctest --output-on-failure -j $(JOBS) $(CTEST_FLAGS)

clean:
	rm -rf $(BUILD_DIR)
