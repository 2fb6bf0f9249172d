# valvemon: two commands on a machine that has only Python 3.11.
#   make demo   set up (virtual environment from the lockfile) and run the demo
#   make test   set up and run the whole test suite (what CI runs)
PYTHON ?= python3
UV_VERSION := 0.13.9
TOOLS := .tools
UV := $(TOOLS)/bin/uv
VENV := .venv
export PREFECT_SERVER_ANALYTICS_ENABLED := false
export PREFECT_HOME ?= $(CURDIR)/.prefect
# hard links from uv's cache into .venv: 151 packages in 0.3 s instead of 20 s as copies (uv copies
# by itself where the cache is on another file system)
export UV_LINK_MODE := hardlink

.PHONY: setup demo test bench clean chromium

$(UV):
	$(PYTHON) -m venv $(TOOLS)
	$(TOOLS)/bin/pip install --quiet uv==$(UV_VERSION)

# the dependencies' .pyc files are written once here; without them every run with
# PYTHONDONTWRITEBYTECODE=1 (as on CI) compiles ~1200 modules again (~10 s a command). Their own
# test suites (2,657 of 10,977 files, never imported) are left out: 11.7 s instead of 16.5
$(VENV)/.synced: $(UV) uv.lock pyproject.toml
	$(UV) sync --frozen --python $(PYTHON)
	$(VENV)/bin/python -m compileall -q -j 0 -x '/tests/' "$$($(VENV)/bin/python -c 'import sysconfig; print(sysconfig.get_path("purelib"))')"
	touch $@

# numba compiles each kernel on its first call in a process (~90 s of CPU in all) and caches it
# beside its source: paid here, on a tiny plant through the pipeline, not by the first command
# (flows/common/kernel_cache.py; its two parts side by side under -j)
KERNEL_PARTS := $(VENV)/.kernels-snapshot $(VENV)/.kernels-continuous
$(VENV)/.kernels-%: $(VENV)/.numba-cache-checked
	OPENBLAS_NUM_THREADS=1 $(VENV)/bin/python -m flows.common.kernel_cache $*
	touch $@

# our own packages are installed editable (uv compiles only site-packages): compile them too,
# on every setup (compileall skips what is up to date)
setup: $(VENV)/.synced $(VENV)/.numba-cache-checked $(KERNEL_PARTS)
	$(VENV)/bin/python -m compileall -q flows transforms model schemas

# numba's on-disk cache (__pycache__/*.nbi, *.nbc) checks only the kernel's own file: a kernel that
# calls one of another module compiled in keeps the old callee after that module changes (a pull
# or a merge). Drop every cached kernel when any of our sources is newer than the last check.
SOURCES := $(shell find flows transforms model schemas -name '*.py' 2>/dev/null)
$(VENV)/.numba-cache-checked: $(SOURCES) | $(VENV)/.synced
	find flows transforms model schemas -name '*.nb[ic]' -delete
	touch $@

demo:
	$(MAKE) --no-print-directory -j2 setup
	$(VENV)/bin/valvemon demo

# the report's HTML is checked in headless Chromium (tests/report): install Debian's package when
# it is missing and we may (CI runs as root on a fresh machine); otherwise that test is skipped
chromium:
	@if [ ! -x /usr/bin/chromium ] && [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
		echo "installing chromium (Debian package) for the report's rendering test"; \
		apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; \
	fi

# pytest rewrites every test module's asserts (~5 s of CPU a process) and caches that beside it,
# except under PYTHONDONTWRITEBYTECODE=1 (as on CI): written here once, every xdist worker reads
# it (collection 4.6 s instead of 9.7 a worker). The reference plant's cached kernels are dropped
# with it: a cached kernel would keep an old callee, as numba's cache above (~5 s to compile again)
TEST_SOURCES := $(shell find tests -name '*.py' 2>/dev/null)
$(VENV)/.tests-compiled: $(TEST_SOURCES) | $(VENV)/.synced
	find tests -name '*.nb[ic]' -delete
	env -u PYTHONDONTWRITEBYTECODE $(VENV)/bin/python -m pytest --collect-only -q -p no:cacheprovider >/dev/null
	touch $@

# the set-up (its two kernel parts side by side), the tests' rewritten asserts and Chromium's
# install, which on a fresh machine waits ~26 s on the network and dpkg, all at once (-j3)
# Three xdist workers on two cores: some tests wait on their subprocesses (the Prefect API, serve,
# the command line's), and two workers left 9 % of the cores idle: back to back, the same CPU
# (586-590 s) took 325 s of wall with two, 300 with three. OPENBLAS_NUM_THREADS=1: workers each with
# their own BLAS threads spun against each other (the discrepancy tests' least squares: 41 s of
# CPU for 39 s of wall, 16 for 19 without)
test:
	$(MAKE) --no-print-directory -j3 setup chromium $(VENV)/.tests-compiled
	OPENBLAS_NUM_THREADS=1 $(VENV)/bin/python -m pytest -n 3 --dist loadgroup --durations=15

bench: setup
	$(VENV)/bin/python bench/simulate.py

clean:
	rm -rf $(VENV) $(TOOLS) .prefect
