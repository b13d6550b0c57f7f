# The two commands of the README, and a few for developers.
#   make run   install what is missing, build, serve the built-in demo on 127.0.0.1:8080
#   make test  install what is missing, build, run every test (and the unit tests under
#              ASan + UBSan)
BUILD      ?= build
ASAN_BUILD ?= build-asan
TSAN_BUILD ?= build-tsan
JOBS       ?= $(shell nproc)
CMAKE_FLAGS ?=
ifdef CI
CMAKE_FLAGS += -DTERRAD_WERROR=ON
endif

.PHONY: all deps build run test test-asan tsan bench clean

all: build

deps:
	./scripts/install-deps

build: deps
	cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=RelWithDebInfo $(CMAKE_FLAGS) >/dev/null
	cmake --build $(BUILD) -j $(JOBS)

run: build
	./$(BUILD)/terrad serve

test: build test-asan
	cd $(BUILD) && ctest --output-on-failure -j $(JOBS)

test-asan: deps
	cmake -S . -B $(ASAN_BUILD) -DCMAKE_BUILD_TYPE=Debug -DTERRAD_SANITIZE=ON $(CMAKE_FLAGS) >/dev/null
	cmake --build $(ASAN_BUILD) -j $(JOBS)
	cd $(ASAN_BUILD) && ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
		ctest --output-on-failure -j $(JOBS) -L 'unit|hardcases'

# The concurrency tests under ThreadSanitizer, terrad included: the tile store alone
# (snapshots during preloads, evictions and a stream of edits) and the heights endpoint
# over HTTP (renders during a stream of edits, an edit racing a preload). A race makes
# terrad or the test exit 66. A few minutes on two cores (mostly the build).
tsan: deps
	cmake -S . -B $(TSAN_BUILD) -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTERRAD_TSAN=ON $(CMAKE_FLAGS) >/dev/null
	cmake --build $(TSAN_BUILD) -j $(JOBS) --target terrad test_tilestore test_server_edit
	cd $(TSAN_BUILD) && TSAN_OPTIONS="halt_on_error=1 exitcode=66 second_deadlock_stack=1" \
		ctest --output-on-failure -R '^(server_tilestore|server_edit)$$'

# `terrad bench` runs build/terrad-bench (tests/bench), built beside terrad by `build`.
bench: build
	./$(BUILD)/terrad bench --out docs

clean:
	rm -rf $(BUILD) $(ASAN_BUILD) $(TSAN_BUILD)
