# Two commands set everything up on a fresh Debian 12 machine:
#   make run    install what is missing, build, start the node on its embedded simulated robot
#   make test   install what is missing, build, run every test (CTest summary) in the release
#               tree, then again under ASan+UBSan, then the threaded tests under TSan
# Other targets: build, test-release, debug, asan, test-asan, tsan, test-tsan, soak-ci, bench,
# load-bench, fuzz, format, package (the .deb, docs/PACKAGING.md), cross-arm64, test-arm64,
# package-arm64 (docs/ARM64.md), clean.

BUILD_DIR   ?= build/release
DEBUG_DIR   ?= build/debug
ASAN_DIR    ?= build/asan
TSAN_DIR    ?= build/tsan
FUZZ_DIR    ?= build/fuzz
ARM64_DIR   ?= build/arm64
JOBS        ?= $(shell nproc)
GENERATOR   := -G Ninja
CMAKE_FLAGS ?=
# `make test` checks the packages once, then runs its phases with DEPS empty.
DEPS        ?= deps

.PHONY: cross-arm64 test-arm64 package-arm64 package all deps build run test test-sanitizers sanitizer-phases test-release soak-ci debug asan test-asan tsan test-tsan bench load-bench fuzz format clean

all: build

deps:
	@bash scripts/install-deps.sh

$(BUILD_DIR)/build.ninja:
	cmake -S . -B $(BUILD_DIR) $(GENERATOR) -DCMAKE_BUILD_TYPE=Release $(CMAKE_FLAGS)

build: $(DEPS) $(BUILD_DIR)/build.ninja
	cmake --build $(BUILD_DIR) -j $(JOBS)

# The Debian package: build/release/package/rcan_<version>_<arch>.deb (docs/PACKAGING.md).
package: build
	cd $(BUILD_DIR) && cpack -G DEB

run: build
	$(BUILD_DIR)/bin/rcan selfcheck
	$(BUILD_DIR)/bin/rcand $(RCAND_ARGS)

# Every test three times: the release tree, ASan+UBSan, and the threaded programs under TSan
# (docs/TESTING.md). Each phase also runs alone: test-release, test-asan, test-tsan.
test: deps
	@echo "== [1/3] release build + full suite ($(BUILD_DIR))"
	@$(MAKE) --no-print-directory DEPS= test-release
	@$(MAKE) --no-print-directory DEPS= sanitizer-phases
	@echo "== release, ASan+UBSan and TSan suites passed"

test-sanitizers: deps
	@$(MAKE) --no-print-directory DEPS= sanitizer-phases

sanitizer-phases:
	@echo "== [2/3] ASan+UBSan build + full suite ($(ASAN_DIR))"
	@$(MAKE) --no-print-directory DEPS= test-asan
	@echo "== [3/3] TSan build + threaded tests ($(TSAN_DIR))"
	@$(MAKE) --no-print-directory DEPS= test-tsan

test-release: build
	ctest --test-dir $(BUILD_DIR) --output-on-failure -j $(JOBS) $(CTEST_ARGS)

# The five-minute soak (docs/SOAK.md): the hour's traffic and judgement against a real rcand,
# outside `make test` (scripts/soak.sh runs the hour).
soak-ci: build
	timeout 480 $(BUILD_DIR)/bench/soak --minutes 5 --rcand $(BUILD_DIR)/bin/rcand --rcan $(BUILD_DIR)/bin/rcan

debug: deps
	cmake -S . -B $(DEBUG_DIR) $(GENERATOR) -DCMAKE_BUILD_TYPE=Debug $(CMAKE_FLAGS)
	cmake --build $(DEBUG_DIR) -j $(JOBS)

# Sanitizer trees: every report fails the run, including one from an rcand a test started
# (scripts/sanitized-ctest.sh collects them). CTEST_ARGS, e.g. "-R safety".
$(ASAN_DIR)/build.ninja:
	cmake -S . -B $(ASAN_DIR) $(GENERATOR) -DCMAKE_BUILD_TYPE=RelWithDebInfo -DRCAN_SANITIZE=ON -DRCAN_BUILD_BENCH=OFF $(CMAKE_FLAGS)

asan: $(DEPS) $(ASAN_DIR)/build.ninja
	cmake --build $(ASAN_DIR) -j $(JOBS)

test-asan: asan
	scripts/sanitized-ctest.sh asan $(ASAN_DIR) $(JOBS) $(CTEST_ARGS)

$(TSAN_DIR)/build.ninja:
	cmake -S . -B $(TSAN_DIR) $(GENERATOR) -DCMAKE_BUILD_TYPE=RelWithDebInfo -DRCAN_TSAN=ON -DRCAN_BUILD_BENCH=OFF $(CMAKE_FLAGS)

tsan: $(DEPS) $(TSAN_DIR)/build.ninja
	cmake --build $(TSAN_DIR) -j $(JOBS)

test-tsan: tsan
	scripts/sanitized-ctest.sh tsan $(TSAN_DIR) $(JOBS) $(CTEST_ARGS)

bench: build
	@for b in $(BUILD_DIR)/bench/*_bench; do echo "== $$b"; $$b; done

# End-to-end figures of rcand against a bare Beast server (README "Performance").
# LOAD_BENCH_ARGS, e.g. "--seconds 10 --data-root /dev/shm".
load-bench: build
	$(BUILD_DIR)/bench/load_bench $(LOAD_BENCH_ARGS)

fuzz: deps
	CXX=clang++-14 cmake -S . -B $(FUZZ_DIR) $(GENERATOR) -DCMAKE_BUILD_TYPE=RelWithDebInfo -DRCAN_FUZZ=ON -DRCAN_WERROR=OFF -DRCAN_BUILD_TESTS=OFF -DRCAN_BUILD_BENCH=OFF
	cmake --build $(FUZZ_DIR) -j $(JOBS) --target fuzzers

# arm64: Debian's cross toolchain against an arm64 sysroot (scripts/arm64-sysroot.sh installs
# the toolchain and qemu-user, and unpacks the sysroot); the core, crypto and audit tests run
# under qemu-user. Outside `make test`: docs/ARM64.md.
$(ARM64_DIR)/build.ninja:
	cmake -S . -B $(ARM64_DIR) $(GENERATOR) -DCMAKE_BUILD_TYPE=Release -DCMAKE_TOOLCHAIN_FILE=cmake/toolchain-arm64.cmake -DRCAN_BUILD_BENCH=OFF $(CMAKE_FLAGS)

cross-arm64:
	@bash scripts/arm64-sysroot.sh
	@$(MAKE) --no-print-directory $(ARM64_DIR)/build.ninja
	cmake --build $(ARM64_DIR) -j $(JOBS)

test-arm64: cross-arm64
	ctest --test-dir $(ARM64_DIR) --output-on-failure -j $(JOBS) -L '^(core|crypto|audit|package)$$' $(CTEST_ARGS)

package-arm64: cross-arm64
	cd $(ARM64_DIR) && cpack -G DEB

format:
	clang-format -i $$(git ls-files '*.cpp' '*.h')

clean:
	rm -rf build
