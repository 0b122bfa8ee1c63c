"""Results of a run: JSON writing and ``report.md`` (the figures and the video:
`cgda_jax.experiment.figures`)."""

from __future__ import annotations

import json
import logging
import math
import pathlib
from typing import Any

import numpy as np

from cgda_jax.experiment.config import ExperimentConfig

log = logging.getLogger("cgda_jax")


def jsonable(x: Any) -> Any:
    """``x`` with NumPy values made plain and non-finite floats ``None``."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def write_json(path: pathlib.Path, data: dict) -> None:
    """``data`` (`jsonable`) as indented JSON into ``path``."""
    path.write_text(json.dumps(jsonable(data), indent=2) + "\n")


def _with_unit(value: float, unit: str | None) -> str:
    return f"{value:.4g} {unit}" if unit else f"{value:.4g}"


def _limit(value) -> str:
    return "-" if value is None else f"{value:g}"


def motion_lines(motion: dict, optimiser_feasible: bool | None) -> list[str]:
    """The report's feasibility section: the motion against the robot's limits
    (`cgda_jax.sim.motion_check.motion_report`)."""
    lim = motion["limits"]
    col = motion.get("collisions")
    verdict = "feasible" if motion["feasible"] else "NOT feasible: " + "; ".join(
        motion["problems"])
    lines = ["## Feasibility", "",
             f"Independent check of the reported joints: **{verdict}**."]
    free = [j for j in motion["joints"] if lim["velocity"].get(j) is None]
    if free:  # "-" in the limit column: say what the verdict then covers
        lines += ["", f"**No speed limit** for {', '.join(free)} (neither the model "
                  "nor `[robot.limits]` gives one): \"feasible\" here means free of "
                  "collisions and of moves over the step cap, not within the robot's "
                  "speeds. Set `[robot.limits]` (e.g. `velocity = 3.0`) to judge them."]
    if optimiser_feasible is not None:
        lines += ["", "The strategy's own check (every move at its collision "
                  f"samples): {'feasible' if optimiser_feasible else 'infeasible'}."]
    lines += ["", f"Approach from the start posture: {motion['approach_s']:.2f} s; "
              f"every other move {motion['move_s']:.2f} s; whole motion "
              f"{motion['duration_s']:.1f} s; moves changing a joint by more than "
              f"{motion['max_step_deg']:g} deg: {motion['moves_over_max_step']}."]
    if col is not None:
        a, b = col["pair"]
        lines += ["", f"Collisions ({col['pairs']} pairs, {col['postures_checked']} "
                  f"postures): closest {a} - {b}, {col['worst_distance_m'] * 1e3:.1f} "
                  f"mm ({'penetration' if col['worst_distance_m'] < 0 else 'clear'}; "
                  f"allowed {motion['penetration_allowed_m'] * 1e3:g} mm), move "
                  f"{col['move'] + 1}."]
    contact = motion.get("physics_contact")
    if contact:
        a, b = contact["pair"]
        lines += ["", f"Deepest contact in the physics replay: {a} - {b}, "
                  f"{contact['deepest_m'] * 1e3:.1f} mm."]
    ex = motion.get("executed")
    if ex:  # dynamic mode: the replayed path, judged as the search judged its own
        worst = max(ex["tracking_deg"], key=ex["tracking_deg"].get)
        into = (f"{ex['pair'][0]} - {ex['pair'][1]}, move {ex['move'] + 1}"
                if ex["pair"] else "no pairs")
        lines += ["", f"Executed path (the physics replay, {ex['postures_checked']} "
                  f"postures): deepest penetration {ex['penetration_m'] * 1e3:.1f} mm "
                  f"({into}; allowed {ex['penetration_allowed_m'] * 1e3:g} mm); "
                  f"tracking error {ex['tracking_deg'][worst]:.1f} deg ({worst}; "
                  f"limit {ex['tracking_limit_deg']:g} deg); at the force limit "
                  f"{100 * ex['saturation']:.1f} % of the worst move (limit "
                  f"{100 * ex['saturation_limit']:g} %)."]
    dyn = "measured_speed" in motion
    head = ["joint", "peak speed [rad/s]", "limit", "peak acc. [rad/s^2]", "limit"]
    if dyn:
        head += ["measured speed", "peak effort [N m]", "limit",
                 "tracking at waypoint ends, max [deg]"]
    # the approach apart: a run whose points all share one posture travels only
    # there (its later moves are 0)
    head += ["approach [deg]", "largest move after it [deg]",
             "travel, approach included [deg]"]
    lines += ["", "| " + " | ".join(head) + " |", "|---" * len(head) + "|"]
    for j in motion["joints"]:
        row = [j, f"{motion['peak_speed'][j]:.2f}", _limit(lim["velocity"][j]),
               f"{motion['peak_acceleration'][j]:.2f}",
               _limit(lim["acceleration"][j])]
        if dyn:
            eff = motion["peak_effort"].get(j)
            row += [f"{motion['measured_speed'][j]:.2f}",
                    "-" if eff is None else f"{eff:.1f}", _limit(lim["effort"][j]),
                    f"{motion['tracking_error_deg'][j]:.1f}"]
        approach = (motion.get("approach_deg") or {}).get(j)
        row += ["-" if approach is None else f"{approach:.0f}",
                f"{motion['largest_step_deg'][j]:.0f}",
                f"{motion['travel_deg'][j]:.0f}"]
        lines.append("| " + " | ".join(row) + " |")
    if motion.get("tracking_note"):
        lines += ["", f"**Tracking:** {motion['tracking_note']}."]
    return lines


def _force(lo, hi) -> str:
    """A force range; None or +-inf: no bound."""
    lo, hi = (v if v is not None and math.isfinite(v) else None for v in (lo, hi))
    if lo is None and hi is None:
        return "none"
    if lo is not None and hi is not None and lo == -hi:
        return f"+-{hi:g}"
    low = "-inf" if lo is None else f"{lo:g}"
    return f"[{low}, {'inf' if hi is None else f'{hi:g}'}]"


def control_lines(control: dict) -> list[str]:
    """The report's control section: how dynamic mode drove each held joint
    (`cgda_jax.sim.drives.ControlPlan.as_dict`)."""
    pds = any(d["drive"] != "position" for d in control["joints"])
    gravity = (f"gravity compensation in the PD {'on' if control['gravity'] else 'off'}"
               if pds else "no joint-space PD (every held joint is a position servo "
               "of the model, carrying gravity itself)")
    lines = ["## Control", "",
             f"`robot.control.mode = \"{control['mode']}\"`, {gravity}.", "",
             "| joint | drive | actuator | kp | kd | force limit [N m] | gravity "
             "compensated | gains from |", "|---" * 8 + "|"]
    for d in control["joints"]:
        drive = "position servo" if d["drive"] == "position" else "joint-space PD"
        act = (f"{d['actuator']} ({d['actuator_kind']})" if d["actuator"]
               else "none (added)")
        src = d.get("sources", {})
        lines.append(f"| {d['joint']} | {drive} | {act} | {d['kp']:.4g} | "
                     f"{d['kd']:.4g} | {_force(d['force_lo'], d['force_hi'])} | "
                     f"{'yes' if d['gravity'] else 'no'} | kp {src.get('kp', '-')}, "
                     f"kd {src.get('kd', '-')} |")
    return lines


def export_rows(export: dict | None, unit: str | None) -> list[str]:
    """The report's row of the exported trajectory replayed on MuJoCo C
    (`cgda_jax.experiment.compute.export_check`)."""
    if not export:
        return []
    if not export.get("exported"):
        return [f"| exported trajectory | not exported: {export.get('reason')} |"]
    rep = export["replay"]
    where = (f"timestep {rep['timestep']:g} s" if "timestep" in rep
             else f"{rep['substeps']} sub-steps per move")
    lim = {k: "no limit" if v is None else f"{v:.2f}"
           for k, v in export["limit_ratio"].items()}
    within = all(v is None or v <= 1 + 1e-6 for v in export["limit_ratio"].values())
    # "method" is how results written before the profiles were named said it
    how = {"min_jerk": "minimum jerk", "ruckig": f"ruckig {export.get('ruckig', '')}"
           }.get(export.get("profile"), export.get("method", "?")).strip()
    return [(f"| exported trajectory ({how}, {export['rate_hz']:g} Hz, "
            f"{export['samples']} samples, {export['duration_s']:.2f} s) replayed on "
            f"MuJoCo C at {where} | success {export['success']}, max point error "
            f"{_with_unit(export['max_point_error'], unit)}, max feature difference "
            f"{export['max_feature_difference']:.3g}; samples "
            f"{'within' if within else 'OVER'} the limits (peak / limit: velocity "
            f"{lim['velocity']}, acceleration {lim['acceleration']}) |")]


def _aimed(result: dict, unit: str | None) -> str:
    """", each point evolved to X" where the strategy's ``aim`` was below 1."""
    info = result.get("info") or {}
    if "aim_tolerance" not in info:
        return ""
    return (f", each point evolved to {_with_unit(info['aim_tolerance'], unit)}: "
            f"aim {info['aim']:g}")


def _not_relocalized(table: dict | None) -> str:
    """The feature columns the closed loop could not re-localize, by reason."""
    if not table:
        return ""
    by: dict[str, list[str]] = {}
    for col, why in table.items():
        by.setdefault(why, []).append(col)
    return " (not " + "; ".join(f"{', '.join(c)}: {w}" for w, c in by.items()) + ")"


def _calibration(cal: dict | None) -> str:
    """The closed loop's joint offsets estimated from the measured tool, in words."""
    if not cal:
        return ""
    offs = ", ".join(f"{x:.2f}" for x in cal["offsets_deg"])
    return (f"; joint offsets estimated from the measured tool: {offs} deg "
            f"({cal['pairs']} postures, tool fit {cal['residual_mm']:.2g} mm rms)")


def _loop_options(options: dict | None) -> str:
    """The closed loop's settings that differ from the defaults, in words."""
    if not options:
        return ""
    said = []
    if options.get("step_tolerance"):
        said.append(f"steps evolved to {options['step_tolerance']:g}")
    if options.get("relocate_objects") is False:
        said.append("objects not re-localized")
    if options.get("correct") is False:
        said.append("targets not corrected")
    if options.get("calibrate") is False:
        said.append("joint offsets not estimated")
    return "; " + ", ".join(said) if said else ""


def reality_rows(reality: dict | None, unit: str | None) -> list[str]:
    """The report's row of the result executed open loop on the mismatched world
    (`cgda_jax.experiment.compute.reality_check`) and, for OET, the row of the
    closed loop there (`cgda_jax.experiment.compute.closed_loop_check`)."""
    if not reality:
        return []
    drawn = ", ".join(
        f"{k} {[round(x, 4) for x in v] if isinstance(v, list) else v}"
        for k, v in reality["mismatch"].items())
    if not reality.get("executed"):
        return [f"| open loop on the mismatched world | not executed: "
                f"{reality.get('reason')} |"]
    per = ", ".join(f"{e:.3g}" for e in reality["point_errors"])
    rows = [(f"| open loop on the mismatched world (seed {reality['seed']}: {drawn}) "
             f"| success {reality['success']}, max point error "
             f"{_with_unit(reality['max_point_error'], unit)}; per point: {per} |")]
    closed = reality.get("closed_loop")
    if closed:
        per = ", ".join(f"{e:.3g}" for e in closed["point_errors"])
        rows.append(
            f"| closed loop (OET) on the same world | success {closed['success']}, "
            f"max point error {_with_unit(closed['max_point_error'], unit)}; per "
            f"point: {per}; {closed['steps']} steps, planning "
            f"{sum(closed['planning_s']):.3g} s, execution "
            f"{sum(closed['execution_s']):.3g} s; objects re-localized from "
            f"{', '.join(closed.get('relocalized') or []) or 'no feature'}"
            f"{_not_relocalized(closed.get('not_relocalized'))}"
            f"{_calibration(closed.get('calibration'))}"
            f"{_loop_options(closed.get('options'))} |")
    return rows


def generations_text(result: dict, max_generations: int) -> str:
    """The report's generations: the count the progress line ends on and the fitness
    plot's axis spans, with what it counts (IE: the slowest point's, its points
    evolving side by side; IET, OET: summed over the points in run order; restarts
    and backtracks included) against ``max_generations`` (one try's budget; FTE:
    the whole run's)."""
    g, info = int(result["generations"]), result.get("info") or {}
    per = info.get("point_generations") or info.get("step_generations")
    tries = info.get("point_tries") or info.get("step_tries") or [info.get("tries", 1)]
    most = max([int(t) for t in tries if t is not None] + [1])
    budget = (f"{most} tries of at most {max_generations}" if most > 1
              else f"at most {max_generations} a try")
    if result["strategy"] == "ie" and per:
        return (f"{g} (the slowest point's: the points evolve side by side; "
                f"{sum(per)} over all {len(per)} points; {budget})")
    if per:
        what = "steps" if result["strategy"] == "oet" else "points"
        return f"{g} (summed over the {len(per)} {what} in run order; {budget})"
    if result["strategy"] == "fte":  # one budget over all its tries
        return (f"{g} ({most} tries, " if most > 1 else f"{g} (") + (
            f"at most {max_generations} in all)")
    return f"{g} ({budget})"


def not_met_hint(cfg: ExperimentConfig, result: dict) -> str | None:
    """For an execution that missed its tolerance: how many points met it, the
    nearest approach, and what to try when the goal may be out of reach (the
    reach check, the workspace); None for a run that met it."""
    if result.get("kind") == "recognition" or result.get("success"):
        return None
    errors = np.asarray([np.inf if e is None else e for e in result["point_errors"]],
                        float)
    tol, unit = result["tolerance"], result.get("error_unit")
    met = int(np.sum(errors < tol))
    worst = int(np.argmax(errors))
    text = (f"{met} of {len(errors)} points within the tolerance; the farthest, "
            f"point {worst + 1}, ends {_with_unit(errors[worst], unit)} away")
    off = (result.get("info") or {}).get("unreachable_points")
    if off:
        return text + (f"; the reach check found {len(off)} point(s) out of the "
                       "arm's reach (`info.unreachable_points`: nearest approach "
                       "each): move the goal into the workspace.")
    if met == 0 or errors[worst] > 10 * tol:
        reach = ("`--set strategy.options.reach_check=true` samples the arm's "
                 "workspace first and names each unreachable point with its "
                 "nearest approach; " if cfg.strategy.name == "ie" else "")
        return text + (". The goal may be out of the arm's reach: "
                       f"{reach}move the goal (`data.centre`) in front of the arm "
                       "or choose other joints (`robot.joints`).")
    return text + (": more generations, a larger population or "
                   "`strategy.options.restarts` may close the gap.")


def _z(value) -> str:
    return "-" if value is None or not np.isfinite(value) else f"{value:.2f}"


def selection_rows(selection: dict | None) -> list[str]:
    """The ``[selection]`` of a recognition run: per action the z-scores of its
    features and demonstrations, a discarded one struck through."""
    if not selection:
        return []

    def cells(part: dict) -> str:
        return ", ".join(
            f"{n} {_z(z)}" if keep else f"~~{n} {_z(z)}~~"
            for n, z, keep in zip(part["names"], part["zscores"], part["selected"]))

    lines = ["", f"Selection (normalization {selection['normalization']}, alpha "
             f"{selection['alpha']:g}; z-scores, discarded struck through):", "",
             "| action | features | demonstrations |", "|---|---|---|"]
    for action, rec in selection["actions"].items():
        feats, dems = rec.get("features"), rec.get("demonstrations")
        lines.append(f"| {action} | {cells(feats) if feats else 'all'} | "
                     f"{cells(dems) if dems else 'all'} |")
    if "features" in selection:
        lines += ["", "Features kept (by at least one action): "
                  + ", ".join(selection["features"]) + "."]
    return lines


def report_markdown(cfg: ExperimentConfig, result: dict,
                    plots: list[str] | None = None) -> str:
    """``report.md`` of a run (``plots``: the PNGs to show, default
    ``result["plots"]``)."""
    unit = result.get("error_unit")
    lines = [f"# {cfg.name}", ""]
    if cfg.description:
        lines += [cfg.description, ""]
    if result["kind"] == "recognition":
        acts = result["actions"]
        loo = result.get("split") == "leave_one_out"
        lines += [
            f"Recognition, {len(result['features'])} features "
            f"({', '.join(result['features'])}), metric {result['metric']}"
            + (", leave one out: each repetition recognized against the actions "
               "generalized from all the others." if loo else "."),
            "",
            "| test \\ generalized | " + " | ".join(acts) + " |",
            "|---" * (len(acts) + 1) + "|",
        ]
        for k, (q, row) in enumerate(zip(result["truth"],
                                         np.asarray(result["cost_matrix"]))):
            best = int(np.argmin(row))
            cells = [f"**{v:.4g}**" if j == best else f"{v:.4g}" for j, v in enumerate(row)]
            name = f"{q.lower()} ({result['queries'][k]})" if loo else q.lower()
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
        lines += ["", f"Accuracy: {result['accuracy']:.0%}."]
        lines += selection_rows(result.get("selection"))
    else:
        lines += [
            f"Strategy {result['strategy'].upper()} ({cfg.strategy.algorithm}, population "
            f"{cfg.strategy.population_size}) on {cfg.robot.model}, joints "
            f"{', '.join(cfg.robot.joints)}.",
            "",
            "| figure | value |", "|---|---|",
            f"| success | {result['success']} |",
            f"| points | {result['points']} |",
            f"| max point error | {_with_unit(result['max_point_error'], unit)} "
            f"(tolerance {_with_unit(result['tolerance'], unit)}"
            f"{_aimed(result, unit)}) |",
            f"| final fitness | {_with_unit(result['final_fitness'], unit)} |",
            f"| generations | {generations_text(result, cfg.strategy.max_generations)} |",
            f"| evaluations | {result['evaluations']} |",
            f"| run time (compiled generations) | {result['wall_time_s']:.2f} s |",
            f"| compile time | {result['compile_time_s']:.2f} s |",
        ]
        if result.get("invalid_evaluations"):
            lines += [f"| diverged (invalid) evaluations | "
                      f"{result['invalid_evaluations']} of {result['evaluations']} |"]
        phys, replay = result.get("physics"), result.get("replay")
        if phys:
            lines += [
                f"| physics | {phys['backend']}, {phys['waypoint_s']:.3g} s per "
                f"waypoint, timestep {phys['timestep']:g} s, "
                f"{len(phys['welded_joints'])} joints welded |",
            ]
        if result.get("substeps"):
            lines += [f"| kinematic sub-steps per waypoint | {result['substeps']} |"]
        if replay:
            where = (f"timestep {replay['timestep']:g} s (MuJoCo C)"
                     if "timestep" in replay
                     else f"{replay['substeps']} sub-steps per waypoint")
            lines += [
                f"| replay at {where} | "
                f"success {replay['success']}, max point error "
                f"{_with_unit(replay['max_point_error'], unit)}, max feature "
                f"difference {replay['max_feature_difference']:.3g} |",
            ]
        lines += export_rows(result.get("export"), unit)
        lines += reality_rows(result.get("reality"), unit)
        hint = not_met_hint(cfg, result)
        if hint:
            lines += ["", f"**Not met.** {hint}"]
        if phys and phys.get("control"):
            lines += [""] + control_lines(phys["control"])
        if result.get("motion"):
            lines += [""] + motion_lines(result["motion"],
                                         (result.get("info") or {}).get("feasible"))
        render = result.get("render")
        if render and render.get("ok"):
            lines += ["", "The robot executing the best trajectory (paper Fig. 8/11):", "",
                      f"![robot executing]({render['gif']})"]
            if render.get("mp4"):
                lines += ["", f"Video: [{render['mp4']}]({render['mp4']})"]
        elif render:
            lines += ["", f"Frames not rendered: {render['reason']} (set MUJOCO_GL=egl "
                      "or osmesa; `output.render = false` turns rendering off)."]
    if result.get("selected_demonstrations"):
        lines += ["", "Demonstrations kept by the selection (normalization "
                  f"{cfg.selection.normalization}, alpha {cfg.selection.alpha:g}): "
                  + ", ".join(result["selected_demonstrations"]) + "."]
    if result.get("feature_labels"):
        lines += ["", "Features: " + ", ".join(result["feature_labels"]) + "."]
    plots = sorted(plots if plots is not None else result.get("plots", []))
    if plots:
        lines += ["", "Plots:", ""] + [f"![{p}]({p})" for p in plots]
    return "\n".join(lines) + "\n"
