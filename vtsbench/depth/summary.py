"""`vtsbench calibrate` as one call: check the options, fit, write the calibration and its report,
and return the summary a person reads (per held-out press, their mean, by solver, what was
written)."""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from ..errors import VtsError
from .calibration import SOLVERS, calibrate, save_calibration
from .report import circles_vs_labels, write_report

#: The mapping options each method takes; any other given is an error naming it.
METHOD_OPTIONS: dict[str, frozenset[str]] = {
    "lut": frozenset({"bins", "cells"}),
    "poly": frozenset({"degree", "pos_degree"}),
    "mlp": frozenset({"width", "depth", "epochs", "pos_degree"}),
}
#: Press ids listed in the last line before "..." (all of them are in report.json).
LISTED_IDS = 8


def check_options(method: str, options: Mapping[str, Any], solver: str) -> None:
    """A VtsError naming the options (as --flags) that do not apply to METHOD, or a bad solver."""
    allowed = METHOD_OPTIONS.get(method, frozenset())
    wrong = sorted(k for k, v in options.items() if v is not None and k not in allowed)
    if wrong:
        opts = ", ".join("--" + k.replace("_", "-") for k in wrong)
        raise VtsError(f"{opts} does not apply to --method {method}")
    if solver not in SOLVERS:
        raise VtsError(f"unknown solver {solver!r} (use dct, dst or masked)")


def calibrate_to_file(recordings: str | Path, out: str | Path, *, method: str,
                      holdout: int | None = None, seed: int = 0,
                      mm_per_px: float | None = None, background: str | Path | None = None,
                      estimate_background: bool = False, report: str | Path | None = None,
                      solver: str = "dct", device: str = "auto",
                      options: Mapping[str, Any] | None = None, circles: str = "label",
                      markers: str = "auto", rim_cv: bool = False,
                      log: Callable[[str], None] = print) -> list[str]:
    """Fit a calibration from the presses of RECORDINGS, save it to OUT and its report (default
    OUT.report beside it); the summary lines. OPTIONS are the mapping's (None: not given)."""
    given = dict(options or {})
    check_options(method, given, solver)
    out = Path(out)
    t0 = time.perf_counter()
    run = calibrate(recordings, method=method, holdout=holdout, seed=seed, mm_per_px=mm_per_px,
                    background=background, estimate_background=estimate_background,
                    solver=solver, device=device,
                    options={k: v for k, v in given.items() if v is not None}, log=log,
                    circles=circles, markers=markers, rim_cv=rim_cv)
    save_calibration(run.calibration, out)
    folder = Path(report) if report is not None else out.with_name(out.name + ".report")
    png, _ = write_report(run, folder)
    return summary_lines(run, out, png, method, time.perf_counter() - t0)


def summary_lines(run: Any, out: Path, png: Path, method: str, seconds: float) -> list[str]:
    """The lines printed after a calibration: each held-out press's errors, their mean, the
    solvers side by side, and what was written (with the presses dropped or doubted)."""
    lines = []
    for r in run.held_out:
        e = r.errors
        lines.append(f"  {r.press.id}: gradient RMSE {e['gradient_rmse']:.4f}, plane-aligned "
                     f"RMSE {e['plane_aligned_rmse_mm']:.4f} mm, contact RMSE "
                     f"{e['contact_rmse_mm']:.4f} mm, peak error "
                     f"{e['peak_depth_error_mm']:+.4f} mm ({r.reference})")
    if run.held_out:
        m = run.calibration.fit["holdout_mean"]

        def mm(k: str, sign: str = "") -> str:
            v = m.get(k)
            return "n/a" if v is None else f"{v:{sign}.4f} mm"

        lines.append(f"held-out mean over {len(run.held_out)} presses: plane-aligned RMSE "
                     f"{mm('plane_aligned_rmse_mm')}, contact RMSE {mm('contact_rmse_mm')}, "
                     f"peak error {mm('peak_depth_error_mm', '+')}, gradient RMSE "
                     f"{m['gradient_rmse']:.4f}")
        vs = run.calibration.fit.get("holdout_vs_labels") or {}
        if vs.get("plane_aligned_rmse_mm") is not None:
            lines.append(f"  the same {vs['presses']} held-out press(es) scored against their "
                         f"labelled circles: plane-aligned RMSE {vs['plane_aligned_rmse_mm']:.4f}"
                         " mm (set beside a run with --circles label and the same --seed)")
        parts = [f"{s} {mm(s + '_contact_rmse_mm')}, {mm(s + '_peak_depth_error_mm', '+')}, "
                 f"{mm(s + '_min_depth_mm', '+')}, {mm(s + '_border_abs_mm')}"
                 for s in SOLVERS]
        lines.append("  by solver (contact RMSE, peak error, lowest depth, mean |depth| on the "
                     "border): " + "; ".join(parts)
                     + " (masked: zero outside the contact, for absolute depth)")
    agree = circles_vs_labels(run.presses)
    if agree is not None:
        missed = agree["presses"] - agree["detected"]
        lines.append(
            f"detected circles against the {agree['presses']} labels: centre off a median "
            f"{agree['centre_median_px']:.2f} px (at most {agree['centre_max_px']:.2f}), "
            f"{agree['share_centre']:.0%} within {agree['within_px']:g} px; radius a median "
            f"{agree['radius_median']:+.1%}, {agree['share_radius']:.0%} within "
            f"{agree['within_radius']:.0%}; {agree['share_both']:.0%} within both"
            + (f" ({missed} labelled press(es) with no circle detected)" if missed else "")
            + (f"; beyond {agree['within_px']:g} px, farthest first: "
               f"{', '.join(agree['beyond_px'][:LISTED_IDS])}"
               f"{', ...' if len(agree['beyond_px']) > LISTED_IDS else ''}"
               if agree["beyond_px"] else ""))
    caveat = "".join(
        f"; {len(ids)} press(es) {what} ({', '.join(ids[:LISTED_IDS])}"
        f"{', ...' if len(ids) > LISTED_IDS else ''}, see report.json)"
        for ids, what in ((run.dropped, "dropped"), (run.doubted, "doubted"),
                          (run.retried, "with a circle detected again"))
        if ids)
    lines.append(f"wrote {out} ({method}, {run.calibration.n_presses} training presses) and "
                 f"{png} in {seconds:.1f} s{caveat}")
    return lines
