"""The test tiers, and a build cache of the session's own.

Tiers are markers (pyproject.toml registers them; the README names the command of each):

- compile: needs a C compiler (builds generated packages, runs them);
- tools: needs cmake, clang, valgrind or the sanitizers beside the compiler;
- heavy: no compiler, but too slow for the fast tier (SymPy on longer chains);
- benchmark, slow: long runs, not in the default run;
- fast: every test that has none of the above, given the marker here.

Fast and heavy tests run with CC pointing at no compiler, so one that builds by mistake fails
instead of passing slowly.

Builds go to a per-session cache directory (CHAINGEN_CACHE_DIR), so the tests neither read nor
fill the user's cache, and subprocesses of CLI tests share it; pytest-xdist's workers share one.
"""
from __future__ import annotations

import os
import signal

import pytest

SLOW_TIERS = ("compile", "tools", "heavy", "benchmark", "slow")
NO_COMPILER = "chaingen-fast-tier-has-no-c-compiler"


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(items):
    """Mark every test outside the slow tiers `fast` (before -m selects)."""
    for item in items:
        if not any(item.get_closest_marker(tier) for tier in SLOW_TIERS):
            item.add_marker(pytest.mark.fast)


def pytest_configure(config):
    """Ctrl-C as on a terminal, also when the tests run as a background job: a shell starts
    those with SIGINT ignored, which every child would inherit, and the tests that interrupt
    a run (test_faults, test_sweep) would see it run on."""
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture(scope="session", autouse=True)
def isolated_build_cache(tmp_path_factory):
    """The session's build cache. Under pytest-xdist the workers share one (in the run's
    common temporary directory): the cache is made for concurrent use (builders of one library
    take turns, runtime/build.py), so a package that tests on two workers need is generated
    and compiled once, not once per worker."""
    previous = os.environ.get("CHAINGEN_CACHE_DIR")
    if os.environ.get("PYTEST_XDIST_WORKER"):
        cache = tmp_path_factory.getbasetemp().parent / "chaingen-cache"
        cache.mkdir(exist_ok=True)
    else:
        cache = tmp_path_factory.mktemp("chaingen-cache")
    os.environ["CHAINGEN_CACHE_DIR"] = str(cache)
    yield
    if previous is None:
        os.environ.pop("CHAINGEN_CACHE_DIR", None)
    else:
        os.environ["CHAINGEN_CACHE_DIR"] = previous


_ORIGINAL_CC = os.environ.get("CC")


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item):
    """A compiler-free test (fast, heavy), and the fixtures it sets up, see no compiler; the
    others the real one."""
    if item.get_closest_marker("fast") or item.get_closest_marker("heavy"):
        os.environ["CC"] = NO_COMPILER
    elif _ORIGINAL_CC is None:
        os.environ.pop("CC", None)
    else:
        os.environ["CC"] = _ORIGINAL_CC
