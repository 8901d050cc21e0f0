"""`chaingen simulate`'s summary of a run: steps, time, errors, Newton's work.

Its maxima of the energy, balance and constraint errors are over the samples kept: with
`--every N` > 1 each says so (the C loop tracks no error of its own, so a larger error between
the samples is not seen); `--every 1` gives the maximum over every step.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..scene.labels import scheme_label


def run_summary(result, settings, out: Path | None) -> str:
    label = scheme_label(result.method, result.quadrature, result.order)
    per_step = result.wall_time / max(result.n_steps, 1)
    # Adaptive steps cover each interval dt with steps of their own (counted below).
    step = "interval" if result.adaptive else "step"
    # The maxima are over the samples kept: with every > 1, not over every step (the C loop
    # tracks no error of its own), and the summary says so.
    over = ("" if result.every == 1 else
            f" over the {len(result.samples)} samples kept (every {result.every} {step}s)")
    lines = [
        f"{result.scene}: {label}, dt {settings.dt:g} s, t_end {result.n_steps * settings.dt:g} s",
        f"  {step + 's':<22} {result.n_steps} ({len(result.samples)} samples, "
        f"every {result.every})",
        f"  wall time (C loop)     {result.wall_time:.4g} s ({per_step * 1e6:.3g} us/{step})",
        f"  t_realtime             {result.t_realtime:.3g}",
        # A controlled run's energy is the closed loop's H_d, named as the balance line does.
        f"  max |energy error|     {np.abs(result.energy_error).max():.3e} J"
        + (f" (|{result.storage} - {result.storage}_0|)" if result.storage != "H" else "")
        + over,
    ]
    if result.has_flows:
        lines += [
            f"  input work, dissipated {result.input_work[-1]:.6g} J, "
            f"{result.dissipated[-1]:.6g} J",
            f"  max |balance error|    {np.abs(result.balance_error).max():.3e} J "
            f"({result.storage} - {result.storage}_0 - work + dissipated){over}",
        ]
    lines += [
        f"  max |constraint error| {result.constraint_error.max():.3e}{over}",
        f"  Newton iterations      mean {result.mean_newton_iterations:.2f}, "
        f"max {result.max_newton_iterations}",
    ]
    if result.full_newton_fallbacks or result.split_steps:
        lines.append(f"  Newton fallbacks       {result.full_newton_fallbacks} steps by full "
                     f"Newton, {result.split_steps} steps split into halves")
    if result.adaptive:
        lines.append(f"  adaptive steps         {result.accepted_steps} accepted, "
                     f"{result.rejected_steps} rejected, dt from {result.smallest_dt:.3g} to "
                     f"{result.largest_dt:.3g} s (rtol {settings.rtol:g}, atol {settings.atol:g})")
    if out is not None:
        lines.append(f"  trajectory             {out}")
    return "\n".join(lines)
