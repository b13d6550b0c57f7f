# The two commands of the README, and a few for developers.
#   make run   install what is missing, build, serve the built-in demo on 127.0.0.1:8080
#   make test  install what is missing, build, run every test (and the unit tests under
#              ASan + UBSan)
BUILD      ?= build
ASAN_BUILD ?= build-asan
JOBS       ?= $(shell nproc)
CMAKE_FLAGS ?=
ifdef CI
CMAKE_FLAGS += -DTERRAD_WERROR=ON
endif

.PHONY: all deps build run test test-asan bench clean

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

# `terrad bench` runs build/terrad-bench (tests/bench), built beside terrad by `build`.
bench: build
	./$(BUILD)/terrad bench --out docs

clean:
	rm -rf $(BUILD) $(ASAN_BUILD)
