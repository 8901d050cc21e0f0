"""Per-step ratio against MuJoCo RK4, the previous build and the new one measured alternately
in one run: python perf_pair.py OLD_PYTHON NEW_PYTHON ROUNDS (each an environment with its
chaingen installed; PERF_N=3,20 the chain lengths). Prints a table."""
import os
import statistics
import subprocess
import sys

old, new, rounds = sys.argv[1], sys.argv[2], int(sys.argv[3])
CHILD = str(__import__("pathlib").Path(__file__).with_name("perf_child.py"))

SIZES = map(int, os.environ.get("PERF_N", "3,20").split(","))
cases = [(m, n) for n in SIZES for m in ("es", "vi", "midpoint")]
print(f"{'method':9} {'n':>3} {'old ns':>10} {'new ns':>10} {'old/RK4':>8} {'new/RK4':>8} "
      f"{'new/old':>8} {'its old':>8} {'its new':>8}", flush=True)
for method, n in cases:
    steps = 4000 if n == 3 else 1000
    children = {}
    for label, python in (("old", old), ("new", new)):
        child = subprocess.Popen([python, CHILD, method, str(n), "0.01", str(steps)],
                                 stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                                 cwd="/tmp")
        assert child.stdout.readline().strip() == "ready", label
        children[label] = child
    ratios = {"old": [], "new": []}
    ours = {"old": [], "new": []}
    its = {}
    for r in range(rounds):
        for label in (("old", "new") if r % 2 == 0 else ("new", "old")):
            child = children[label]
            child.stdin.write("go\n")
            child.stdin.flush()
            step_ns, mujoco_ns, iterations = map(float, child.stdout.readline().split())
            ratios[label].append(step_ns / mujoco_ns)
            ours[label].append(step_ns)
            its[label] = iterations
    for child in children.values():
        child.stdin.close()
        child.wait()
    ro, rn = statistics.median(ratios["old"]), statistics.median(ratios["new"])
    print(f"{method:9} {n:>3} {statistics.median(ours['old']):>10.0f} "
          f"{statistics.median(ours['new']):>10.0f} {ro:>8.3f} {rn:>8.3f} {rn / ro:>8.3f} "
          f"{its['old']:>8.3f} {its['new']:>8.3f}", flush=True)
