# Two commands set everything up on a fresh Debian 12 machine:
#   make run    install what is missing, build, start the node on its embedded simulated robot
#   make test   install what is missing, build, run every test (CTest summary)
# Other targets: build, debug, asan, bench, load-bench, fuzz, format, clean.

BUILD_DIR   ?= build/release
DEBUG_DIR   ?= build/debug
ASAN_DIR    ?= build/asan
FUZZ_DIR    ?= build/fuzz
JOBS        ?= $(shell nproc)
GENERATOR   := -G Ninja
CMAKE_FLAGS ?=

.PHONY: all deps build run test debug asan test-asan bench load-bench fuzz format clean

all: build

deps:
	@bash scripts/install-deps.sh

$(BUILD_DIR)/build.ninja:
	cmake -S . -B $(BUILD_DIR) $(GENERATOR) -DCMAKE_BUILD_TYPE=Release $(CMAKE_FLAGS)

build: deps $(BUILD_DIR)/build.ninja
	cmake --build $(BUILD_DIR) -j $(JOBS)

run: build
	$(BUILD_DIR)/bin/rcan selfcheck
	$(BUILD_DIR)/bin/rcand $(RCAND_ARGS)

test: build
	ctest --test-dir $(BUILD_DIR) --output-on-failure -j $(JOBS)

debug: deps
	cmake -S . -B $(DEBUG_DIR) $(GENERATOR) -DCMAKE_BUILD_TYPE=Debug $(CMAKE_FLAGS)
	cmake --build $(DEBUG_DIR) -j $(JOBS)

asan: deps
	cmake -S . -B $(ASAN_DIR) $(GENERATOR) -DCMAKE_BUILD_TYPE=RelWithDebInfo -DRCAN_SANITIZE=ON -DRCAN_BUILD_BENCH=OFF $(CMAKE_FLAGS)
	cmake --build $(ASAN_DIR) -j $(JOBS)

test-asan: asan
	ctest --test-dir $(ASAN_DIR) --output-on-failure -j $(JOBS)

bench: build
	@for b in $(BUILD_DIR)/bench/*_bench; do echo "== $$b"; $$b; done

# End-to-end figures of rcand against a bare Beast server (README "Performance").
# LOAD_BENCH_ARGS, e.g. "--seconds 10 --data-root /dev/shm".
load-bench: build
	$(BUILD_DIR)/bench/load_bench $(LOAD_BENCH_ARGS)

fuzz: deps
	CXX=clang++-14 cmake -S . -B $(FUZZ_DIR) $(GENERATOR) -DCMAKE_BUILD_TYPE=RelWithDebInfo -DRCAN_FUZZ=ON -DRCAN_WERROR=OFF -DRCAN_BUILD_TESTS=OFF -DRCAN_BUILD_BENCH=OFF
	cmake --build $(FUZZ_DIR) -j $(JOBS) --target fuzzers

format:
	clang-format -i $$(git ls-files '*.cpp' '*.h')

clean:
	rm -rf build
