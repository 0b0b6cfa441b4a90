"""How long discovery takes and how well it does: the cases and figures behind ``wall-inspector bench-discover``.

Timing (:mod:`wall_inspector.bench_discover` times the ``discover`` command itself): a 60 s,
100 Hz wall survey with the two hidden effects of :data:`EFFECTS` (wall suction and extra
linear drag), target :data:`TARGET_S_PER_MINUTE` per minute of log as a command; then
several one-minute surveys of one vehicle, each in its own steady wind of :data:`FLIGHT_WINDS`
with the quadratic drag :data:`FLIGHTS_DRAG`, fitted together, target :data:`TARGET_S_FLIGHTS`
for five.

Acceptance (:func:`acceptance_records`, :func:`summarise`, :func:`format_summary`): hidden-effect
logs (:mod:`discovery.hidden_effects`): every form of :data:`~discovery.hidden_effects.FORMS`
(the library's effects and the literature's fuller forms) singly and the pairs of
:data:`~discovery.hidden_effects.PAIRS`, plus clean logs of every scenario of
:data:`CLEAN_SCENARIOS`, at log rates cycling through :data:`RATES`, for each seed; the figures
are the share named right with no spurious effect (target >= 95 %), the parameters within
10 %, the held-out force-gap reductions (target >= 80 %) and whether clean logs name nothing.
"""

from __future__ import annotations

from collections.abc import Iterator

TARGET_S_PER_MINUTE = 5.0
EFFECTS = "wall_suction:k_s=4.1,d_thr=0.132;linear_drag:D=0.2/0.2/0.2"
#: several flights of one vehicle, each in its own steady wind (m/s, world x and y): one model with per-flight winds
FLIGHT_WINDS = ((1.5, 0.5), (-2.0, 1.0), (2.5, -1.5), (0.5, 3.0), (-3.0, -2.0))
FLIGHTS_DRAG = (0.1, 0.1, 0.08)  # N s^2/m^2, the quadratic drag flown in every wind
TARGET_S_FLIGHTS = 20.0  # s for five flights of a minute at 100 Hz, as a command


RATES = (100.0, 50.0, 200.0, 500.0, 1000.0)
CLEAN_SCENARIOS = ("wall-sweep", "wall-survey", "survey", "ground-survey", "ceiling-survey", "floor-to-ceiling")


def acceptance_records(seeds: list[int], duration: float) -> Iterator[dict]:
    """Fly and discover every acceptance log of every seed in turn, yielding each log's record
    (:func:`discovery.hidden_effects.fly_and_discover`'s, with its ``case``) as it is done."""
    import numpy as np

    from discovery.hidden_effects import FORMS, PAIRS, draw, draw_pair, fly_and_discover

    index = 0
    for seed in seeds:
        rng = np.random.default_rng(np.random.SeedSequence([seed, 0xACC]))
        cases = []
        for form in FORMS:
            effect, fly_kwargs = draw(form, rng)
            cases.append(([effect], fly_kwargs, form))
        cases += [(*draw_pair(pair, rng), "+".join(pair)) for pair in PAIRS]
        for effects, fly_kwargs, label in cases:
            record = fly_and_discover(effects, fly_kwargs, 1000 * seed + index, RATES[index % len(RATES)], duration)
            record["case"] = label
            index += 1
            yield record
        for scenario in CLEAN_SCENARIOS:
            record = fly_and_discover([], {"scenario": scenario}, 1000 * seed + index, RATES[index % len(RATES)],
                                      duration)
            record["case"] = f"clean {scenario}"
            index += 1
            yield record


def summarise(records: list[dict], seeds: list[int], duration: float) -> dict:
    """The acceptance figures of ``records`` (as :func:`discovery.hidden_effects.fly_and_discover`
    returns them, with their ``case``) as a dict; :func:`format_summary` says them in words."""
    import numpy as np

    ended = [r for r in records if r["ended_early"]]
    records_flown = [r for r in records if not r["ended_early"]]
    hidden = [r for r in records_flown if r["flown"]]
    clean = [r for r in records_flown if not r["flown"]]
    right = [r for r in hidden if r["named_right"]]
    param_errors = [e for r in right for e in r["param_errors"].values() if e is not None]
    within = [r for r in right if all(e is not None and e <= 0.10 for e in r["param_errors"].values())]
    gaps = [r["gap_reduction"] for r in hidden]
    # misses of 10 %, told apart by the fit's own standard errors: within 2 the log does not
    # determine the parameter to 10 % (noise), beyond 2 the estimate is off by more than its noise
    off = [(f"{r['case']} (log seed {r['seed']}, {r['rate_hz']:g} Hz)", k, e, r.get("param_errors_in_std", {}).get(k),
            [] if r["form_right"] else r.get("forms_left_open", [])) for r in right
           for k, e in r["param_errors"].items() if e is None or e > 0.10]
    off_noise = [o for o in off if o[3] is not None and o[3] <= 2.0 and not o[4]]
    summary = {
        "logs_with_hidden_effects": len(hidden),
        "named_right_no_spurious": len(right),
        "named_right_share": len(right) / len(hidden) if hidden else None,
        "forms_right": sum(r["form_right"] for r in right),
        "spurious_logs": sum(bool(r["spurious"]) for r in hidden),
        "logs_with_all_params_within_10_percent": len(within),
        "worst_param_error": max(param_errors, default=None),
        "median_param_error": float(np.median(param_errors)) if param_errors else None,
        "params_off_by_more_than_10_percent": [{"case": c, "param": k, "error": e, "error_in_std": z,
                                               "forms_left_open": f} for c, k, e, z, f in off],
        "params_off_within_2_std": len(off_noise),
        "worst_force_gap_reduction": min(gaps, default=None),
        "logs_with_gap_reduction_80_percent": sum(g >= 0.8 for g in gaps),
        "clean_logs": len(clean),
        "clean_logs_nothing_named": sum(not r["named"] for r in clean),
        "flights_ended_early": len(ended), "seeds": seeds, "duration_s": duration,
    }
    return summary


def format_summary(summary: dict) -> str:
    """:func:`summarise`'s figures in words, one line each (what ``bench-discover --acceptance`` prints)."""
    hidden, right = summary["logs_with_hidden_effects"], summary["named_right_no_spurious"]
    off = summary["params_off_by_more_than_10_percent"]
    lines = [
        f"named right with nothing spurious: {right}/{hidden} "
        f"({100 * summary['named_right_share']:.0f} %, target >= 95 %); fuller form right in "
        f"{summary['forms_right']}/{right}",
        f"all parameters within 10 %: {summary['logs_with_all_params_within_10_percent']}/{right} logs named right; "
        f"worst parameter error {100 * (summary['worst_param_error'] or 0):.1f} %, median "
        f"{100 * (summary['median_param_error'] or 0):.1f} %",
    ]
    for o in off:
        error, z, forms = o["error"], o["error_in_std"], o["forms_left_open"]
        lines.append(f"  off by more than 10 %: {o['case']}: {o['param']} "
                     f"{'missing' if error is None else f'{100 * error:.1f} %'}"
                     f"{'' if z is None or forms else f', {z:.1f} standard errors'}"
                     f"{f' (plain form kept: the report names {forms} as left open, with the manoeuvre)' if forms else ''}")
    if off:
        within_noise = summary["params_off_within_2_std"]
        left_open = sum(1 for o in off if o["forms_left_open"])
        lines.append(f"  of these, {within_noise} within 2 standard errors of the truth (the log does not determine "
                     f"them to 10 %), {left_open} of a fuller form the report names as left open, "
                     f"{len(off) - within_noise - left_open} farther or missing")
    lines += [
        f"held-out force gap reduced by >= 80 %: {summary['logs_with_gap_reduction_80_percent']}/{hidden}; "
        f"worst reduction {100 * summary['worst_force_gap_reduction']:.0f} %",
        f"clean logs with nothing named: {summary['clean_logs_nothing_named']}/{summary['clean_logs']}",
    ]
    if summary["flights_ended_early"]:
        lines.append(f"flights that ended early (collision) and were not counted: {summary['flights_ended_early']}")
    return "\n".join(lines)
