"""Print the error table of docs/integrand.md: every integrand mode against adaptive
quadrature (scipy) over a grid of β, γ spans, extinctions and phase functions.

    .venv/bin/python tools/integrand_report.py     # ~15 s, needs scipy (the `test` extra)
"""
from __future__ import annotations

import math

import numpy as np

from clrays.scene.model import Phase
from clrays.stages.integrand import LIGHT_KINDS, build_integrand, integrand_exact, segment_radiance


# The representative setting of the report: relative errors do not depend on σs or the
# power, and for point lights σt enters only through σt·d_el (≤ 1 here).
REPORT_D_EL = 2.0
REPORT_SIGMA_S = (0.1, 0.2, 0.3)
REPORT_POWER = (10.0, 20.0, 30.0)
REPORT_SIGMA_T = {"zero": (0.0, 0.0, 0.0), "small": (0.01, 0.02, 0.04), "medium": (0.2, 0.3, 0.5)}
REPORT_PHASES = (Phase(), Phase("hg", 0.3), Phase("hg", -0.5))
REPORT_BETAS = (1e-3, 3e-3, 1e-2, 3e-2, 0.1, 0.3, 0.6, 1.0, 1.4, 1.8, 2.2, 2.6, 2.9, 3.05,
                math.pi - 3e-2, math.pi - 1e-2)
# Point light: fractions of the whole ray [0, π-β); directional: distances s (m), s_max = 50.
REPORT_POINT_SPANS = ((0.0, 1.0), (0.0, 0.25), (0.25, 0.5), (0.5, 0.75), (0.75, 0.95), (0.1, 0.9), (0.4, 0.41))
REPORT_DIRECTIONAL_SPANS = ((0.0, 50.0), (0.0, 5.0), (3.0, 20.0), (30.0, 45.0), (10.0, 10.5))
REPORT_S_MAX = 50.0
# Segments carrying less than this fraction of their ray's radiance are left out.
REPORT_FLOOR = 1e-6


def _reference(light_kind, sigma_t, phase, beta, gamma0, gamma1) -> np.ndarray:
    """∫ I dγ over [γ0, γ1] by adaptive quadrature (scipy), per channel."""
    from scipy.integrate import quad

    hints = [math.pi - beta - k * beta for k in (0.5, 1, 2, 5, 20)] if light_kind == "point" else []
    hints = [p for p in hints if gamma0 < p < gamma1] or None
    return np.array([quad(lambda gm: integrand_exact(light_kind, REPORT_SIGMA_S, sigma_t, phase, REPORT_POWER,
                                                     REPORT_D_EL, beta, gm)[c],
                          gamma0, gamma1, epsabs=0.0, epsrel=1e-11, limit=500, points=hints)[0] for c in range(3)])


def error_report(n_beta=256, n_gamma=1024) -> list[dict]:
    """Relative error of every mode against quadrature over the REPORT_* grid.

    Returns one dict per (light, mode, phase class) with keys light, mode, phase, count
    (segments × channels), whole_median, whole_max (whole rays), median, max (all
    segments), max_to_ray (largest |error| / whole-ray radiance) and worst (the segment
    with the largest relative error)."""
    modes = (("table", {}), ("svd", {"rank": 1}), ("svd", {"rank": 4}), ("svd", {"rank": 8}), ("analytic", {}))
    stats: dict[tuple, list] = {}
    for light_kind in LIGHT_KINDS:
        for sigma_name, sigma_t in REPORT_SIGMA_T.items():
            for phase in REPORT_PHASES:
                phase_class = "isotropic" if phase.type == "isotropic" else "HG g=0.3, -0.5"
                built = []
                for mode, extra in modes:
                    label = mode + (f" rank {extra['rank']}" if "rank" in extra else "")
                    try:
                        built.append((label, build_integrand(mode, light_kind, REPORT_SIGMA_S, sigma_t, phase,
                                                             REPORT_POWER, REPORT_D_EL, 0.0, math.pi, math.pi,
                                                             n_beta, n_gamma, s_max=REPORT_S_MAX, **extra)))
                    except ValueError:
                        pass  # analytic has no closed form here
                for beta in REPORT_BETAS:
                    if light_kind == "point":
                        spans = [(a * (math.pi - beta), b * (math.pi - beta)) for a, b in REPORT_POINT_SPANS]
                    else:
                        spans = [(a * math.sin(beta), b * math.sin(beta)) for a, b in REPORT_DIRECTIONAL_SPANS]
                    refs = [_reference(light_kind, sigma_t, phase, beta, g0, g1) for g0, g1 in spans]
                    for index, ((g0, g1), ref) in enumerate(zip(spans, refs)):
                        keep = np.abs(ref) > REPORT_FLOOR * np.abs(refs[0])
                        for label, tables in built:
                            value = segment_radiance(tables, beta, g0, g1)
                            err = np.abs(value / ref - 1.0)[keep]
                            to_ray = (np.abs(value - ref) / np.abs(refs[0]))[keep]
                            where = f"σt {sigma_name}, g={phase.g:g}, β={beta:.4g}, γ∈[{g0:.4g}, {g1:.4g}]"
                            stats.setdefault((light_kind, label, phase_class), []).extend(
                                (float(e), float(r), index == 0, where) for e, r in zip(err, to_ray))
    rows = []
    for (light_kind, label, phase_class), errs in stats.items():
        values = np.array([e[0] for e in errs])
        whole = np.array([e[0] for e in errs if e[2]])
        rows.append({"light": light_kind, "mode": label, "phase": phase_class, "count": len(values),
                     "whole_median": float(np.median(whole)), "whole_max": float(whole.max()),
                     "median": float(np.median(values)), "max": float(values.max()),
                     "max_to_ray": max(e[1] for e in errs), "worst": errs[int(values.argmax())][3]})
    return rows


def format_report(rows) -> str:
    """The error table as Markdown."""
    lines = ["| light | mode | phase | whole rays: median | max | all segments: median | max "
             "| max error / ray | worst segment |",
             "|---|---|---|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        lines.append(f"| {r['light']} | {r['mode']} | {r['phase']} | {r['whole_median']:.1e} | "
                     f"{r['whole_max']:.1e} | {r['median']:.1e} | {r['max']:.1e} | {r['max_to_ray']:.1e} | "
                     f"{r['worst']} |")
    return "\n".join(lines)


def main() -> None:
    print(format_report(error_report()))


if __name__ == "__main__":
    main()
