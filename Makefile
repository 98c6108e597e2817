# InstaScene backend: the two commands that matter are `make demo` and `make test`.
# Each installs missing Debian packages first (scripts/install-deps.sh), so either works as the
# very first command on a fresh machine.

BUILD_DIR    ?= build
SANITIZE_DIR ?= build-sanitize
JOBS         ?= $(shell nproc)
CMAKE_FLAGS  ?=

.PHONY: all deps configure build test test-sanitize fuzz load chaos memcheck bench bench-web demo format tidy clean

all: build

deps:
	@scripts/install-deps.sh --check >/dev/null 2>&1 || scripts/install-deps.sh

$(BUILD_DIR)/build.ninja: | deps
	cmake -S . -B $(BUILD_DIR) -G Ninja -DCMAKE_BUILD_TYPE=Release $(CMAKE_FLAGS)

configure: $(BUILD_DIR)/build.ninja

build: deps configure
	cmake --build $(BUILD_DIR) -j $(JOBS)

# Tests run with TMPDIR set to a fresh directory that must be empty again afterwards: no test may
# leave anything behind. It is world-readable: the PostgreSQL test server runs as the postgres user.
test: build
	@tmp=$$(mktemp -d) && chmod 755 $$tmp && cd $(BUILD_DIR) && status=0; \
	  TMPDIR=$$tmp ctest --output-on-failure -j $(JOBS) || status=$$?; \
	  left=$$(find $$tmp -mindepth 1 -maxdepth 2 | head -20); \
	  if [ -n "$$left" ]; then echo "tests left files behind in TMPDIR:"; echo "$$left"; status=1; fi; \
	  rm -rf $$tmp; exit $$status

test-sanitize: deps
	cmake -S . -B $(SANITIZE_DIR) -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DINSTASCENE_SANITIZE=ON -DINSTASCENE_BUILD_BENCHMARKS=OFF
	cmake --build $(SANITIZE_DIR) -j $(JOBS)
	cd $(SANITIZE_DIR) && ASAN_OPTIONS=detect_leaks=1 LSAN_OPTIONS=suppressions=$(CURDIR)/tests/lsan.supp UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 ctest --output-on-failure -j $(JOBS) -L unit

# libFuzzer harnesses under ASan/UBSan (clang), FUZZ_SECONDS each (default 60); not part of `make test`.
fuzz: deps
	scripts/fuzz.sh

# Long runs, not part of `make test` (figures in docs/RELIABILITY.md).
load: build
	scripts/load.sh $(BUILD_DIR)

chaos: build
	scripts/chaos.sh $(BUILD_DIR)

memcheck: build
	scripts/memcheck.sh $(BUILD_DIR)

bench: build
	scripts/bench.sh $(BUILD_DIR)

# The web UI's measurements in Chromium (viewer first frame, event latency); docs/PERFORMANCE.md.
bench-web: build
	scripts/bench_web.sh $(BUILD_DIR)

demo: build
	scripts/demo.sh $(BUILD_DIR)

format:
	git ls-files '*.h' '*.cc' | xargs clang-format -i

tidy: configure
	git ls-files 'common/*.cc' 'clients/*.cc' 'services/*.cc' | grep -v _test.cc | grep -v _benchmark.cc | xargs clang-tidy -p $(BUILD_DIR) --quiet

clean:
	rm -rf $(BUILD_DIR) $(SANITIZE_DIR) build-fuzz demo-out
