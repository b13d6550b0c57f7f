# The two commands of the README, and a few for developers.
#   make run   install what is missing, build, serve the built-in demo on 127.0.0.1:8080
#   make test  install what is missing, build, run every test (and the unit tests under
#              ASan + UBSan), and replay every fuzz corpus (libFuzzer build when clang is
#              installed; the plain replay of ctest -L fuzz always)
#   make soak  SOAK_SECONDS (default 600) of overload on loopback with wrk (scripts/soak):
#              no crash, only 200/202/304/503 (+ Retry-After), memory flat
#   make fuzz  fuzz every target of tests/fuzz for FUZZ_SECONDS (default 600) each, with
#              libFuzzer + ASan + UBSan (clang); prints executions and findings
BUILD      ?= build
ASAN_BUILD ?= build-asan
FUZZ_BUILD ?= build-fuzz
FUZZ_SECONDS ?= 600
FUZZ_TARGETS ?= asc hgt png raw cache request edit maps viewshed render
CLANG ?= $(shell command -v clang 2>/dev/null)
SOAK_SECONDS ?= 600
TSAN_BUILD ?= build-tsan
JOBS       ?= $(shell nproc)
CMAKE_FLAGS ?=
ifdef CI
CMAKE_FLAGS += -DTERRAD_WERROR=ON
endif

.PHONY: all deps build run test test-asan tsan fuzz fuzz-build fuzz-replay soak bench clean

all: build

deps:
	./scripts/install-deps

build: deps
	cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=RelWithDebInfo $(CMAKE_FLAGS) >/dev/null
	cmake --build $(BUILD) -j $(JOBS)

run: build
	./$(BUILD)/terrad serve

test: build test-asan fuzz-replay
	cd $(BUILD) && ctest --output-on-failure -j $(JOBS)

test-asan: deps
	cmake -S . -B $(ASAN_BUILD) -DCMAKE_BUILD_TYPE=Debug -DTERRAD_SANITIZE=ON $(CMAKE_FLAGS) >/dev/null
	cmake --build $(ASAN_BUILD) -j $(JOBS)
	cd $(ASAN_BUILD) && ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
		ctest --output-on-failure -j $(JOBS) -L 'unit|hardcases|fuzz'

# The fuzz targets built with clang's libFuzzer (tests/fuzz; the tree under ASan + UBSan and
# coverage instrumentation). Without clang, `make fuzz` stops and says so, and `make test`
# replays the corpora through the plain driver only (ctest -L fuzz, in both builds above).
# Warnings are gcc's gate (the builds above); clang's other warnings are not errors here.
fuzz-build: deps
	@if [ -z "$(CLANG)" ]; then echo "make fuzz: clang not found (Debian package clang; scripts/install-deps installs it)"; exit 1; fi
	CC=$(CLANG) CXX=$(CLANG)++ cmake -S . -B $(FUZZ_BUILD) -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTERRAD_FUZZ=ON \
		$(filter-out -DTERRAD_WERROR=ON,$(CMAKE_FLAGS)) -DTERRAD_WERROR=OFF >/dev/null
	cmake --build $(FUZZ_BUILD) -j $(JOBS) --target fuzz_targets

fuzz: fuzz-build
	./scripts/fuzz run $(FUZZ_BUILD) $(FUZZ_SECONDS) $(FUZZ_TARGETS)

fuzz-replay:
	@if [ -n "$(CLANG)" ]; then $(MAKE) --no-print-directory fuzz-build && ./scripts/fuzz replay $(FUZZ_BUILD) $(FUZZ_TARGETS); \
	else echo "fuzz-replay: no clang: the corpora are replayed by ctest -L fuzz (plain driver) only"; fi

soak: build
	./scripts/soak --terrad $(BUILD)/terrad --seconds $(SOAK_SECONDS)

# The concurrency tests under ThreadSanitizer, terrad included: the tile store alone
# (snapshots during preloads, evictions and a stream of edits) and the heights endpoint
# over HTTP (renders during a stream of edits, an edit racing a preload). A race makes
# terrad or the test exit 66. A few minutes on two cores (mostly the build).
tsan: deps
	cmake -S . -B $(TSAN_BUILD) -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTERRAD_TSAN=ON $(CMAKE_FLAGS) >/dev/null
	cmake --build $(TSAN_BUILD) -j $(JOBS) --target terrad test_tilestore test_server_edit
	cd $(TSAN_BUILD) && TSAN_OPTIONS="halt_on_error=1 exitcode=66 second_deadlock_stack=1" \
		ctest --output-on-failure -R '^(server_tilestore|server_edit)$$'

# `terrad bench` runs build/terrad-bench (tests/bench), built beside terrad by `build`;
# then what map tiles cost (build/maps-bench, issue 17) and viewsheds against
# gdal_viewshed (scripts/viewshed-bench, issue 18), which the report's summary links.
bench: build
	./$(BUILD)/terrad bench --out docs
	./$(BUILD)/maps-bench . docs/maps-bench.md --runs 5
	./scripts/viewshed-bench --build $(BUILD) --out docs

clean:
	rm -rf $(BUILD) $(ASAN_BUILD) $(FUZZ_BUILD) $(TSAN_BUILD)
