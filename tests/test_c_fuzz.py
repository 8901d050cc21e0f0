"""A fuzz test of a generated package's C entry points under the sanitizers.

A package with every feature (inputs, energy flows, springs, step sensitivities, the energy
check, a composed step of order 4, run-time parameters) is built with
-fsanitize=address,undefined, and tests/c_driver.py's driver calls every entry point with numbers
hypothesis draws: NaN, Inf, zero and negative dt, parameters the scene format refuses, step
counts and strides up to LONG_MAX, holds below 1. Each status must be the one c_driver.expected
gives (a refusal where the numbers are bad, any status where they are good), simulate's u NULL
must be zero torques, simulate_controlled's torques must fill exactly the rows the header gives,
a start whose spring segment has zero length is refused (one fixed case), and the sanitizers
must report nothing (-fno-sanitize-recover: a report ends the driver).

The default run draws FUZZ_EXAMPLES batches of up to BATCH cases.
"""
from __future__ import annotations

import math

import pytest
from c_driver import LONG_MAX, Case, build_driver, generate, mismatches, run_driver
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from helpers import require_tools, scene_path

pytestmark = pytest.mark.tools

SANITIZE = ["-fsanitize=address,undefined", "-fno-omit-frame-pointer",
            "-fno-sanitize-recover=all", "-g", "-O1"]
PARAMETERS = ("links[0].mass", "links[1].inertia", "links[3].length", "links[2].com",
              "springs[0].stiffness", "springs[1].rest_length", "gravity", "links[2].damping",
              "base.fastening")
FUZZ_EXAMPLES = 100
BATCH = 25
LONG_MIN = -LONG_MAX - 1

HOSTILE = [math.nan, math.inf, -math.inf, 0.0, -0.0, -1.0, 5e-324, -5e-324, 1e300, -1e300]
hostile = st.sampled_from(HOSTILE)
huge = st.one_of(st.integers(LONG_MIN, LONG_MAX),
                 st.sampled_from([LONG_MAX, LONG_MIN, LONG_MAX - 1, 0, -1, 1, 2, 3]))


#: A package with a control law (control_torques, issue 34): es, the gains run-time parameters.
CONTROL_PARAMETERS = ("links[0].mass", "springs[0].stiffness", "gravity", "links[2].damping",
                      "control.stiffness[0]", "control.damping[1]", "control.target[0]")


@pytest.fixture(scope="module")
def package(tmp_path_factory):
    require_tools("gcc")
    directory = tmp_path_factory.mktemp("fuzz") / "package"
    generate(directory, "four_link_actuated", "midpoint", 4, PARAMETERS)
    return build_driver(directory, SANITIZE)


@pytest.fixture(scope="module")
def controlled_package(tmp_path_factory):
    require_tools("gcc")
    directory = tmp_path_factory.mktemp("fuzz") / "controlled"
    generate(directory, str(scene_path("four_link_pbc")), "es", 2, CONTROL_PARAMETERS)
    return build_driver(directory, SANITIZE)


@st.composite
def cases(draw, defaults: tuple) -> Case:
    stop = draw(st.booleans())
    return Case(
        dt=draw(st.one_of(hostile, st.floats(1e-4, 0.05))),
        t0=draw(st.one_of(st.just(0.0), hostile, st.floats(-1e3, 1e3))),
        n_steps=draw(huge if stop else st.integers(-3, 24)),
        every=draw(huge if stop else st.one_of(st.integers(-2, 30), huge)),
        hold=draw(st.one_of(st.integers(-2, 30), huge)),
        stop=stop,
        poison=draw(st.one_of(st.just(0.0), hostile)),
        phi=tuple(draw(st.one_of(st.floats(-3.5, 3.5), hostile)) for _ in range(4)),
        u=tuple(draw(st.one_of(st.floats(-50.0, 50.0), hostile)) for _ in range(4)),
        p=tuple(draw(st.one_of(st.just(value), st.just(value), hostile,
                               st.floats(-1e3, 1e3)))
                for value in defaults),
    )


def test_every_entry_point_under_the_sanitizers(package):
    defaults = tuple(package.defaults)
    nan, inf = math.nan, math.inf
    corners = [  # the cases, always run
        Case(0.01, 0.0, LONG_MAX, 1, 1, True, 0.0, (0.3, 0.2, 0.1, 0.0), (0.0,) * 4, defaults),
        Case(0.0, 0.0, 10, 3, 2, False, 0.0, (0.3, 0.2, 0.1, 0.0), (0.0,) * 4, defaults),
        Case(-0.01, 0.0, 10, 3, 2, False, nan, (nan,) * 4, (inf,) * 4, defaults),
        Case(nan, nan, LONG_MIN, LONG_MIN, LONG_MIN, True, inf, (0.0,) * 4, (0.0,) * 4,
             (0.0,) * len(defaults)),
        Case(0.01, 0.0, 20, 3, 2, False, 0.0, (0.3, 0.2, 0.1, 0.0), (1.0, -1.0, 0.5, 0.0),
             defaults),
        # A start whose spring segment s_1 has zero length (base.fastening last):
        # SEGMENT_COLLAPSED from every entry point that takes it.
        Case(0.01, 0.0, 20, 3, 2, False, 0.0, (math.atan2(1.0, 0.3), 0.2, 0.1, 0.0),
             (1.0, -1.0, 0.5, 0.0), defaults[:-1] + (math.hypot(1.0, 0.3),), collapsed=True),
    ]

    fuzz(package, corners)


def fuzz(package, corners: list[Case], examples: int = FUZZ_EXAMPLES) -> None:
    """The corner cases and `examples` batches hypothesis draws, through the driver."""
    @settings(max_examples=examples, deadline=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
    @given(st.lists(cases(tuple(package.defaults)), min_size=1, max_size=BATCH))
    @example(corners)
    def check(batch):
        results, process = run_driver(package, batch)
        assert process.returncode == 0 and "runtime error" not in process.stderr \
            and "Sanitizer" not in process.stderr, process.stderr[-4000:]
        assert mismatches(package, batch, results) == []

    check()


@pytest.mark.slow
def test_control_torques_of_a_controlled_package_under_the_sanitizers(controlled_package):
    """The same fuzz on a package with a control law (four_link_pbc, es, its gains run-time
    parameters): control_torques refuses bad numbers as step does, and is sanitizer clean."""
    package = controlled_package
    assert package.manifest["control"]
    defaults = tuple(package.defaults)
    corners = [Case(0.01, 0.0, 20, 3, 2, False, 0.0, (0.3, 0.2, 0.1, 0.0), (1.0, -1.0, 0.5, 0.0),
                    defaults),
               Case(0.5, 0.0, 3, 1, 1, False, 0.0, (3.0, -2.0, 1.0, 0.5), (50.0,) * 4,
                    defaults),
               Case(0.01, 0.0, 3, 1, 1, False, math.nan, (0.3,) * 4, (0.0,) * 4, defaults)]
    results, _ = run_driver(package, corners[:1])
    assert results[0]["control_torques"] == 0 and results[0]["step"] == 0
    fuzz(package, corners, FUZZ_EXAMPLES // 2)
