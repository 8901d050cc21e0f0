"""One build's timing server for perf_pair.py: builds the bench harness of scaling_scene(n) with
one method, then for each line 'go' on stdin prints 'ours_ns mujoco_ns' (one round each)."""
import sys

from chaingen.generate.package import render_package
from chaingen.studies.bench import scaling
from chaingen.studies.bench.config import HARNESS_FLAGS
from chaingen.studies.bench.harness import Harness
from chaingen.studies.bench.runs import mujoco_step_seconds
from chaingen.symbolic.schemes import build_scheme

method, n, dt, steps = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4])
scene = scaling.scaling_scene(n)
scheme = build_scheme(scene, method, 3)
package = render_package(scheme, sensitivities=False)
initial = getattr(scaling, "_numeric_initial_state", None) or scaling.numeric_initial_state
x0 = initial(scheme, scene)
with Harness(package, flags=HARNESS_FLAGS) as harness:
    harness.time(x0, dt, n_steps=steps // 4, repeats=1)   # warm-up
    print("ready", flush=True)
    for _line in sys.stdin:
        ours = harness.time(x0, dt, n_steps=steps, repeats=1)
        mujoco = mujoco_step_seconds(scene, "RK4", dt, steps, 1)
        print(ours.step_ns, mujoco * 1e9, ours.mean_iterations, flush=True)
