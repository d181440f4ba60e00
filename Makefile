# ltmapper: the two set-up commands (make demo, make test) and friends.
BUILD_DIR ?= build
JOBS ?= $(shell nproc)
CMAKE_FLAGS ?=
CTEST_FLAGS ?=

.PHONY: all deps configure build test bench demo clean

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

clean:
	rm -rf $(BUILD_DIR)
