"""Part 3 of the benchmark: the headline ratios with their targets, from parts 1 and 2."""
from __future__ import annotations

import math
from dataclasses import dataclass

from ...scene import load_reference_scene
from ...scene.labels import scheme_label
from .config import (
    ADAPTIVE_K,
    ADAPTIVE_RTOL,
    ADAPTIVE_SCENE,
    EARLY_T,
    HEADLINE_DT,
    HEADLINE_SCENE,
    HELD_ERRORS,
    TARGET_ADAPTIVE_ENERGY,
    TARGET_ADAPTIVE_OVER_FIXED,
    TARGET_ENERGY_ES,
    TARGET_EQUAL_ERROR,
    TARGET_OURS_OVER_PEER,
    TARGET_RATIO_ES,
    TARGET_RATIO_VI,
    TARGET_SCALING_BUILD,
    TARGET_SCALING_RATIOS,
    TARGET_SCIPY_OVER_ES,
    TARGET_STEP_OVER_EVALUATION,
    TARGET_UNEVEN_RATIOS,
    TRAJECTORY_LEVELS,
    VARIANTS,
    BenchConfig,
    Variant,
)
from .runs import COMPILED_FAMILY, RunRow, method_label
from .scaling import ScalingRow


def interpolate_cost(points, target: float) -> float | None:
    """CPU cost at error `target` by log-log interpolation along work-precision points.

    points: (cost, error) pairs, both > 0 (others are ignored). Taken in order of cost, the
    first (cheapest) pair of neighbours whose errors bracket `target` is interpolated:
    log cost is linear in log error between them. None when no pair brackets `target`, that
    is when it is outside the measured errors: never extrapolated.
    """
    usable = sorted((c, e) for c, e in points if c > 0 and e > 0)
    log_target = math.log(target)
    for (c0, e0), (c1, e1) in zip(usable, usable[1:]):
        if e0 == target:
            return c0
        if (e0 - target) * (e1 - target) <= 0:
            if e1 == e0:
                return c0
            fraction = (log_target - math.log(e0)) / (math.log(e1) - math.log(e0))
            return math.exp(math.log(c0) + fraction * (math.log(c1) - math.log(c0)))
    if len(usable) == 1 and usable[0][1] == target:
        return usable[0][0]
    return None


#: The target of a headline that compares without one.
NO_TARGET = "none"


@dataclass(frozen=True)
class Headline:
    """One row of the headline table. passed: the target met or not, None if not measured;
    for a headline without a target (target NO_TARGET) True once measured."""

    key: str
    claim: str
    variant: str
    measured: str          # the value with what it was computed from
    target: str
    passed: bool | None    # None: not measured

    @property
    def mark(self) -> str:
        if self.target == NO_TARGET and self.passed is not None:
            return "measured"
        return {True: "pass", False: "FAIL", None: "not measured"}[self.passed]


def _find(rows, **match) -> RunRow | None:
    for row in rows:
        if all(getattr(row, key) == value for key, value in match.items()):
            return row
    return None


def _us(seconds: float) -> str:
    return f"{seconds * 1e6:.2f} us"


def _step_ratio_headline(key: str, claim: str, rows, method: str, variant: Variant,
                         target: float) -> Headline:
    ours = _find(rows, method=method, variant=variant.label, dt=HEADLINE_DT)
    peer = _find(rows, method="MuJoCo RK4", dt=HEADLINE_DT)
    target_text = f"<= {target:g}"
    if ours is None or peer is None:
        missing = "our run" if ours is None else "MuJoCo RK4"
        return Headline(key, claim, variant.label, f"{missing} at dt = {HEADLINE_DT:g} s not in "
                        "this run", target_text, None)
    if ours.failure or peer.failure:
        return Headline(key, claim, variant.label,
                        f"failed: {ours.failure or peer.failure}", target_text, False)
    ratio = ours.step_seconds / peer.step_seconds
    return Headline(key, claim, variant.label,
                    f"{ratio:.3f} ({_us(ours.step_seconds)} / {_us(peer.step_seconds)})",
                    target_text, ratio <= target)


def equal_error_headline(rows, variant: Variant, es_method: str) -> Headline:
    """c: CPU time of SciPy DOP853 / CPU time of es at energy error TARGET_EQUAL_ERROR."""
    claim = (f"SciPy DOP853 CPU / {es_method} CPU at equal energy error "
             f"{TARGET_EQUAL_ERROR:.0e} J, standard run")
    target_text = f">= {TARGET_SCIPY_OVER_ES:g}"

    def points(method: str, variant_label: str):
        return [(row.run_seconds, row.energy_error) for row in rows
                if row.method == method and row.variant == variant_label and not row.failure]

    es_points = points(es_method, variant.label)
    scipy_points = points("SciPy DOP853", "-")
    if not es_points or not scipy_points:
        return Headline("c", claim, variant.label, "runs missing from this run", target_text,
                        None)
    scipy_cost = interpolate_cost(scipy_points, TARGET_EQUAL_ERROR)
    errors = [e for _, e in scipy_points]
    if scipy_cost is None:
        return Headline("c", claim, variant.label,
                        f"DOP853's energy errors ({min(errors):.1e} .. {max(errors):.1e} J) do "
                        f"not reach {TARGET_EQUAL_ERROR:.0e}: not measured", target_text, None)
    es_cost = interpolate_cost(es_points, TARGET_EQUAL_ERROR)
    if es_cost is not None:
        ratio = scipy_cost / es_cost
        return Headline("c", claim, variant.label,
                        f"{ratio:.1f} ({scipy_cost * 1e3:.2f} ms / {es_cost * 1e3:.2f} ms, both "
                        "interpolated)", target_text, ratio >= TARGET_SCIPY_OVER_ES)
    es_errors = [e for _, e in es_points]
    if max(es_errors) < TARGET_EQUAL_ERROR:
        # Every es run is more accurate than the target: the cheapest one reaches it, so its
        # cost bounds es's cost at the target from above and the ratio from below.
        cheapest_cost, cheapest_error = min(es_points)
        ratio = scipy_cost / cheapest_cost
        return Headline("c", claim, variant.label,
                        f">= {ratio:.1f} (lower bound: {scipy_cost * 1e3:.2f} ms interpolated / "
                        f"{cheapest_cost * 1e3:.2f} ms, {es_method}'s cheapest run, which is "
                        f"already at {cheapest_error:.1e} J; every {es_method} run is below "
                        f"{TARGET_EQUAL_ERROR:.0e})", target_text,
                        True if ratio >= TARGET_SCIPY_OVER_ES else None)
    return Headline("c", claim, variant.label,
                    f"{es_method}'s energy errors ({min(es_errors):.1e} .. {max(es_errors):.1e} "
                    f"J) do not reach {TARGET_EQUAL_ERROR:.0e}: not measured", target_text, None)


def _setting(row: RunRow) -> str:
    variant = "" if row.variant in ("-", VARIANTS[0].label) else f", {row.variant}"
    return f"{row.method} {row.setting}{variant}"


def _holding(rows, trajectory: float, energy: float) -> RunRow | None:
    """The cheapest run (run CPU) of `rows` whose trajectory error at the early time is at
    most `trajectory` and whose energy error at most `energy`; None if there is none."""
    held = [row for row in rows if not row.failure and row.run_seconds
            and row.early_trajectory_error is not None and row.energy_error is not None
            and row.early_trajectory_error <= trajectory and row.energy_error <= energy]
    return min(held, key=lambda row: row.run_seconds, default=None)


def _closest(rows) -> str:
    measured = [row for row in rows if not row.failure and row.run_seconds]
    trajectories = [row.early_trajectory_error for row in measured
                    if row.early_trajectory_error is not None]
    energies = [row.energy_error for row in measured if row.energy_error is not None]
    if not trajectories or not energies:
        return "no errors measured"
    return f"its best: {min(trajectories):.1e} rad, {min(energies):.1e} J, not in one run"


def held_error_headline(key: str, rows, peer: str, trajectory: float,
                        energy: float) -> Headline:
    """Our best CPU / the peer's, each the cheapest measured run that holds both the
    trajectory error at the early time and the energy error (no interpolation: two errors
    have no common work-precision line). peer: a method label ("MuJoCo RK4"), or
    COMPILED_FAMILY for the cheapest run of any compiled peer."""
    early = min(EARLY_T, rows[0].t_end) if rows else EARLY_T
    name = "the best compiled peer" if peer == COMPILED_FAMILY else peer
    claim = (f"our best CPU / {name}'s, cheapest runs holding {trajectory:.0e} rad at "
             f"t = {early:g} s and {energy:.0e} J, standard run")
    target_text = f"<= {TARGET_OURS_OVER_PEER:g}"
    ours_rows = [row for row in rows if row.family == "chaingen"]
    peer_rows = [row for row in rows
                 if (row.family if peer == COMPILED_FAMILY else row.method) == peer]
    if not ours_rows or not peer_rows:
        missing = ("our runs" if not ours_rows else "no compiled peer's runs"
                   if peer == COMPILED_FAMILY else f"{name}'s runs")
        return Headline(key, claim, "-", f"{missing} not in this run", target_text, None)
    ours, theirs = _holding(ours_rows, trajectory, energy), _holding(peer_rows, trajectory,
                                                                       energy)
    if ours is None or theirs is None:
        who, which = ("ours", ours_rows) if ours is None else (name, peer_rows)
        return Headline(key, claim, "-" if ours is None else ours.variant,
                        f"no run of {who} holds both ({_closest(which)}): not measured",
                        target_text, None)
    ratio = ours.run_seconds / theirs.run_seconds
    return Headline(key, claim, ours.variant,
                    f"{ratio:.3g} ({ours.run_seconds * 1e3:.2f} ms, {_setting(ours)} / "
                    f"{theirs.run_seconds * 1e3:.2f} ms, {_setting(theirs)})", target_text,
                    ratio <= TARGET_OURS_OVER_PEER)


def _cost_at(rows, level: float) -> tuple[float, str] | None:
    """(CPU, bound) at trajectory error `level` along one line's runs: interpolated
    (interpolate_cost; bound ""), or, when every run is more accurate, its cheapest run's
    cost, which bounds the cost at `level` from above (bound "<="); None if not reached."""
    points = [(row.run_seconds, row.early_trajectory_error) for row in rows
              if not row.failure and row.run_seconds and row.early_trajectory_error]
    cost = interpolate_cost(points, level)
    if cost is not None:
        return cost, ""
    if points and max(error for _, error in points) < level:
        return min(points)[0], "<="
    return None


def trajectory_error_headline(rows, level: float) -> Headline:
    """h: every peer's CPU / our best CPU at trajectory error `level` at the early time, each
    line (method and Newton variant) interpolated as in headline c; no target."""
    early = min(EARLY_T, rows[0].t_end) if rows else EARLY_T
    claim = (f"every peer's CPU / our best CPU at trajectory error {level:.0e} rad at "
             f"t = {early:g} s, standard run (interpolated)")
    lines: dict[tuple[str, str], list[RunRow]] = {}
    for row in rows:
        lines.setdefault((row.method, row.variant), []).append(row)
    ours = [(cost, key) for key, line in lines.items() if line[0].family == "chaingen"
            for cost in [_cost_at(line, level)] if cost is not None]
    peers = [key for key, line in lines.items() if line[0].family != "chaingen"]
    if not peers:
        return Headline("h", claim, "-", "no peer in this run: not measured", NO_TARGET, None)
    costs = {key: _cost_at(lines[key], level) for key in peers}
    if not ours:
        errors = [row.early_trajectory_error for row in rows if row.family == "chaingen"
                  and not row.failure and row.early_trajectory_error]
        best = f" (our best: {min(errors):.1e} rad)" if errors else ""
        reached = ", ".join(f"{key[0]} {cost[1] + ' ' if cost[1] else ''}"
                            f"{cost[0] * 1e3:.3g} ms"
                            for key, cost in costs.items() if cost is not None)
        return Headline("h", claim, "-", f"no run of ours reaches it{best}: not measured"
                        + (f"; the peers at it: {reached}" if reached else ""), NO_TARGET, None)
    (our_cost, our_bound), (method, variant) = min(ours)
    parts, missed = [], []
    for key in peers:
        cost = costs[key]
        if cost is None:
            missed.append(key[0])
            continue
        # An upper bound on the peer's cost bounds the ratio from above, one on ours from
        # below; with both, the ratio is only an estimate.
        bound = {("", ""): "", ("<=", ""): "<= ", ("", "<="): ">= "}.get((cost[1], our_bound),
                                                                          "~ ")
        parts.append((cost[0] / our_cost, f"{key[0]} {bound}{cost[0] / our_cost:.3g}"))
    text = (f"ours: {method}{'' if variant in ('-', VARIANTS[0].label) else f', {variant}'} "
            f"{our_bound + ' ' if our_bound else ''}{our_cost * 1e3:.3g} ms; "
            + ", ".join(part for _, part in sorted(parts)))
    if missed:
        text += f"; not reaching {level:.0e} rad: {', '.join(missed)}"
    return Headline("h", claim, variant, text, NO_TARGET, True)


def error_at_cost(points, cost: float) -> float | None:
    """The error at CPU `cost` by log-log interpolation along (cost, error) points: the
    inverse of interpolate_cost, which brackets its second entry (never extrapolated)."""
    return interpolate_cost([(error, c) for c, error in points], cost)


def adaptive_headlines(rows) -> list[Headline]:
    """i: adaptive es at rtol ADAPTIVE_RTOL on ADAPTIVE_SCENE: its trajectory error at the
    early time / that of fixed steps of the same es (order 2, same K, default options) at the
    same CPU (interpolated along their dts), and its energy error over the run."""
    early = min(EARLY_T, rows[0].t_end) if rows else EARLY_T
    fixed_label = scheme_label("es", ADAPTIVE_K, style="short")
    adaptive = next((row for row in rows if row.method == f"{fixed_label} adaptive"
                     and row.setting.startswith(f"rtol = atol = {ADAPTIVE_RTOL:g},")), None)
    claim = (f"{fixed_label} adaptive, rtol = {ADAPTIVE_RTOL:g}: trajectory error at t = "
             f"{early:g} s / that of fixed steps of the same CPU, {ADAPTIVE_SCENE}")
    energy_claim = (f"{fixed_label} adaptive, rtol = {ADAPTIVE_RTOL:g}: max energy error, "
                    f"{ADAPTIVE_SCENE}, standard run")
    targets = (f"<= {TARGET_ADAPTIVE_OVER_FIXED:g}", f"<= {TARGET_ADAPTIVE_ENERGY:.0e} J")
    if adaptive is None or adaptive.failure:
        measured = adaptive.failure if adaptive else "not in this run"
        return [Headline("i", claim, "default options", measured, targets[0], None),
                Headline("i", energy_claim, "default options", measured, targets[1], None)]
    energy = Headline("i", energy_claim, "default options", f"{adaptive.energy_error:.2e} J",
                      targets[1], adaptive.energy_error <= TARGET_ADAPTIVE_ENERGY)
    points = [(row.run_seconds, row.early_trajectory_error) for row in rows
              if row.method == fixed_label and row.variant == VARIANTS[0].label
              and not row.failure and row.early_trajectory_error]
    fixed = error_at_cost(points, adaptive.run_seconds)
    if fixed is None:
        costs = sorted(cost for cost, _ in points)
        span = f"{costs[0] * 1e3:.3g} .. {costs[-1] * 1e3:.3g} ms" if costs else "none"
        return [Headline("i", claim, "default options",
                         f"the adaptive run's {adaptive.run_seconds * 1e3:.3g} ms is outside the "
                         f"fixed runs' CPU ({span}): not measured", targets[0], None), energy]
    ratio = adaptive.early_trajectory_error / fixed
    return [Headline("i", claim, "default options",
                     f"{ratio:.3g} ({adaptive.early_trajectory_error:.2e} rad in "
                     f"{adaptive.run_seconds * 1e3:.3g} ms / {fixed:.2e} rad interpolated at the "
                     "same CPU)", targets[0], ratio <= TARGET_ADAPTIVE_OVER_FIXED), energy]


def compiled_peer_headlines(rows) -> list[Headline]:
    """f (HELD_ERRORS[0]: against MuJoCo RK4 and the best compiled peer), g (HELD_ERRORS[1]:
    against the best compiled peer), h (TRAJECTORY_LEVELS: every peer)."""
    (trajectory_f, energy_f), (trajectory_g, energy_g) = HELD_ERRORS
    return [held_error_headline("f", rows, "MuJoCo RK4", trajectory_f, energy_f),
            held_error_headline("f", rows, COMPILED_FAMILY, trajectory_f, energy_f),
            held_error_headline("g", rows, COMPILED_FAMILY, trajectory_g, energy_g),
            *[trajectory_error_headline(rows, level) for level in TRAJECTORY_LEVELS]]


def headlines(reference: dict[str, list[RunRow]], scaling: list[ScalingRow] | None,
              config: BenchConfig, control=None) -> list[Headline]:
    """Rows a-e of the issue, one per Newton variant, f-h against the compiled peers (over
    every configuration of ours), i of the adaptive steps and j of the control loops
    (`control`: the rows of control.control_study, None if not run), from this run's
    measurements."""
    rows = reference.get(HEADLINE_SCENE, [])
    scene = load_reference_scene(HEADLINE_SCENE)
    es = method_label(scene, "es", 3)
    where = f"{HEADLINE_SCENE}, dt = {HEADLINE_DT:g} s"
    found = []
    for variant in VARIANTS:
        found.append(_step_ratio_headline(
            "a", f"{es} step / MuJoCo RK4 step, {where}", rows, es, variant, TARGET_RATIO_ES))
        es_row = _find(rows, method=es, variant=variant.label, dt=HEADLINE_DT)
        if es_row is None or es_row.failure:
            measured = es_row.failure if es_row else "not in this run"
            found.append(Headline("a", f"{es} max energy error, {where}", variant.label,
                                  measured, f"<= {TARGET_ENERGY_ES:.0e} J", None))
        else:
            found.append(Headline("a", f"{es} max energy error, {where}", variant.label,
                                  f"{es_row.energy_error:.2e} J", f"<= {TARGET_ENERGY_ES:.0e} J",
                                  es_row.energy_error <= TARGET_ENERGY_ES))
        found.append(_step_ratio_headline(
            "b", f"vi step / MuJoCo RK4 step, {where}", rows, "vi", variant, TARGET_RATIO_VI))
        # c compares the fixed steps of order 2 (the composed and adaptive lines are in f-i).
        es_labels = [label for label in dict.fromkeys(row.method for row in rows)
                     if label.split()[0] == "es" and " order " not in label
                     and not label.endswith(" adaptive")] or [es]
        found += [equal_error_headline(rows, variant, label) for label in es_labels]
        found += scaling_headlines(scaling, variant)
        if es_row is None or es_row.failure:
            found.append(Headline("e", f"{es} step / one residual-and-Jacobian evaluation, "
                                  f"{where}", variant.label, "not in this run",
                                  f"<= {TARGET_STEP_OVER_EVALUATION:g}", None))
        else:
            ratio = es_row.step_over_evaluation
            found.append(Headline(
                "e", f"{es} step / one residual-and-Jacobian evaluation, {where}",
                variant.label, f"{ratio:.2f} ({_us(es_row.step_seconds)} / "
                f"{_us(es_row.step_seconds / ratio)})",
                f"<= {TARGET_STEP_OVER_EVALUATION:g}", ratio <= TARGET_STEP_OVER_EVALUATION))
    found += compiled_peer_headlines(rows)
    found += adaptive_headlines(reference.get(ADAPTIVE_SCENE, []))
    found += control_headlines(control)
    return sorted(found, key=lambda headline: headline.key)   # stable: variants stay in order


#: The scaling series' methods as its rows label them.
SCALING_LABELS = ("es K=3", "vi", "midpoint")


def scaling_headlines(scaling: list[ScalingRow] | None, variant: Variant) -> list[Headline]:
    """d: generate + build of each scheme at the n of TARGET_SCALING_BUILD, and the step
    ratios of TARGET_SCALING_RATIOS, on the scaling chain; the step ratios of
    TARGET_UNEVEN_RATIOS on the uneven one."""
    wanted = [(f"{method} generate + build seconds, scaling series n = {n}", method, n,
               f"<= {limit:g} s", limit, True)
              for n, limit in TARGET_SCALING_BUILD for method in SCALING_LABELS]
    wanted += [(f"{method} step / MuJoCo RK4 step, scaling series n = {n}", method, n,
                f"<= {limit:g}", limit, False) for method, n, limit in TARGET_SCALING_RATIOS]
    wanted = [(*entry, "identical") for entry in wanted]
    wanted += [(f"{method} step / MuJoCo RK4 step, uneven scaling chain n = {n}", method, n,
                f"<= {limit:g}", limit, False, "uneven")
               for method, n, limit in TARGET_UNEVEN_RATIOS]
    found = []
    for claim, method, n, target, limit, build, chain in wanted:
        row = None if scaling is None else next(
            (r for r in scaling if r.method == method and r.n == n
             and r.variant == variant.label and r.chain == chain
             and r.gradient == "exact"), None)
        if row is None:
            reason = ("scaling series skipped" if scaling is None
                      else f"n = {n} not in the scaling series")
            found.append(Headline("d", claim, variant.label, reason, target, None))
            continue
        value = row.generate_and_build_seconds if build else row.ratio
        if value is None:
            found.append(Headline("d", claim, variant.label, f"failed: {row.failure}", target,
                                  False))
        elif build:
            found.append(Headline("d", claim, variant.label,
                                  f"{value:.1f} s ({row.generate_seconds:.1f} s generate + "
                                  f"{row.build_seconds:.1f} s build)", target, value <= limit))
        else:
            found.append(Headline("d", claim, variant.label,
                                  f"{value:.2f} ({_us(row.step_seconds)} / "
                                  f"{_us(row.mujoco_step_seconds)}, dt = {row.dt:g} s)",
                                  target, value <= limit))
    return found


def control_headlines(control) -> list[Headline]:
    """j: a step from a Python loop at n = 3, and the C controller's closed loop against the
    open loop (control.py; the table there has the loop with a Python controller too)."""
    from .control import TARGET_C_CONTROLLER_RATIO, TARGET_PYTHON_LOOP_SECONDS, control_scene

    where = f"{control_scene().name}, dt = {HEADLINE_DT:g} s"
    python_claim = f"a step from a Python loop (stepper.step, torques held), {where}"
    c_claim = f"simulate closed by a C controller / open-loop simulate, {where}"
    python_target = f"<= {TARGET_PYTHON_LOOP_SECONDS * 1e6:g} us"
    c_target = f"<= {TARGET_C_CONTROLLER_RATIO:g}"
    if not control:
        return [Headline("j", python_claim, "default options", "not in this run", python_target,
                         None),
                Headline("j", c_claim, "default options", "not in this run", c_target, None)]
    python, c_loop = control[0], control[2]
    return [Headline("j", python_claim, "default options",
                     f"{_us(python.seconds)} ({python.ratio:.2f} x MuJoCo RK4's loop, "
                     f"{_us(python.peer_seconds)})", python_target,
                     python.seconds <= TARGET_PYTHON_LOOP_SECONDS),
            Headline("j", c_claim, "default options",
                     f"{c_loop.ratio:.2f} ({_us(c_loop.seconds)} / {_us(c_loop.peer_seconds)})",
                     c_target, c_loop.ratio <= TARGET_C_CONTROLLER_RATIO)]
